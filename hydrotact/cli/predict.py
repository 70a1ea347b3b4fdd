"""`hydrotact predict`: a trained estimator streamed over a log one sample at a time
(hydrotact.models.StreamingEstimator), written back with the estimates as columns."""

from pathlib import Path

from ._estimates import log_block
from ._output import print_report


def add_parser(subparsers):
    parser = subparsers.add_parser(
        "predict", help="run a trained estimator over a log one sample at a time, as on the sensor; writes the estimates as columns",
        description="Streams the log's readings through the estimator one sample at a time (the same numbers as a batched run) and "
        "writes the log again with a column est_NAME per estimate (est_fx, est_fy, est_fz, est_fn by default; est_x, est_y, est_depth for "
        "a model of those targets), est_theta and est_phi on a sensor with contact angles, and est_contact.",
    )
    parser.add_argument("model", type=Path, metavar="MODEL", help="a model folder from hydrotact train")
    parser.add_argument("log", type=Path, metavar="LOG", help="a log of absolute barometer readings (Parquet or CSV with its metadata)")
    parser.add_argument("-o", "--output", type=Path, required=True, metavar="OUT.parquet", help="the log with the estimates")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    return parser


def run(args) -> None:
    import numpy as np

    from .._files import check_output
    from ..data import BarometerLog, read_log, write_log
    from ..models import StreamingEstimator, load_estimator

    check_output(args.output, suffixes=(".parquet",), what="the log with the estimates")
    model = load_estimator(args.model)
    log = read_log(args.log)
    columns = log_block(model, log, args.log)
    readings = np.column_stack([columns[name] for name in model.channels])
    stream = StreamingEstimator(model)
    rows = [stream.update(reading) for reading in readings]
    names = (*model.spec.targets, *(("theta", "phi") if model.spec.angles else ()))
    estimates = {f"est_{name}": np.array([row[name] for row in rows]) for name in names}
    estimates["est_contact"] = np.array([row["contact_probability"] for row in rows])
    write_log(args.output, BarometerLog(log.metadata, dict(log.columns) | estimates))
    print_report("estimates", {"log": str(args.output), "samples": len(rows), "contact_fraction": float(np.mean(estimates["est_contact"] > 0.5))}, args.json)
