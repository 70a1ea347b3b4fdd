"""`hydrotact export`: a trained estimator as a C header for the sensor's microcontroller
(hydrotact.models.export_c_header)."""

from pathlib import Path

from ._output import print_report


def add_parser(subparsers):
    parser = subparsers.add_parser(
        "export", help="write a trained estimator as a C header for the sensor's microcontroller",
        description="float32 weights, the input normalisation and a reference step function in C99 (<math.h> only).",
    )
    parser.add_argument("model", type=Path, metavar="MODEL", help="a model folder from hydrotact train")
    parser.add_argument("--format", choices=("c",), default="c", help="the output format (default c: one header)")
    parser.add_argument("-o", "--output", type=Path, required=True, metavar="model.h", help="the header to write")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    return parser


def run(args) -> None:
    import json

    from .._files import check_output
    from ..models import export_c_header, load_estimator

    check_output(args.output, suffixes=(".h",), what="the C header")
    model = load_estimator(args.model)
    sensor = json.loads((args.model / "model.json").read_text())["sensor"]
    print_report("exported estimator", export_c_header(model, args.output, sensor), args.json)
