"""`hydrotact generate`: a synthetic dataset of the contact-estimation data-collection
regime (hydrotact.datasets.generate_dataset), with its plots.

Interrupted runs resume: started again with the same arguments into the same folder,
the command picks up the unit responses already computed."""

from pathlib import Path

from .._defaults import DEFAULT_DATASET_MODULUS
from ._arguments import number, number_pair
from ._output import print_report


def add_parser(subparsers):
    from ..datasets import FORCE_DISTRIBUTIONS, REGIMES, TARGETS, DatasetConfig

    d = DatasetConfig.__dataclass_fields__
    default = lambda name: d[name].default
    pair = lambda name, scale=1.0: ",".join(f"{v * scale:g}" for v in default(name))
    parser = subparsers.add_parser(
        "generate", help="generate a synthetic dataset (the contact-estimation data-collection regime): sharded Parquet + manifest + plots",
        description="Contact events uniform by area over the skin, low forces over-sampled, one continuous session at a fixed rate, "
        "labels per sample (Fx, Fy, Fz, Fn, theta, phi, contact, centre of pressure, depth, event, phase). Deterministic for a seed; "
        "an interrupted run resumes when started again with the same arguments.",
    )
    parser.add_argument("--sensor", required=True, metavar="S", help="a built-in sensor (pad5x5, sphere8, ellipsoid8) or a sensor JSON file")
    parser.add_argument("--material", type=Path, metavar="MATERIAL.json", help="the elastomer (e.g. from hydrotact fit); default: elastic, --modulus")
    parser.add_argument(
        "--modulus", type=number, metavar="E",
        help=f"hydroelastic modulus in Pa, elastic, without --material (default {DEFAULT_DATASET_MODULUS:.0e}: "
        "a 3 mm sphere reaches the paper's 8 N at about its own radius on the curved sensors)".replace("e+0", "e"))
    parser.add_argument("--randomise-material", action="store_true", help="draw the material from MATERIAL.json's covariance (domain randomisation; the draw is in the manifest)")
    parser.add_argument("--events", type=int, default=default("events"), metavar="N", help=f"contact events (default {default('events')}, the paper's)")
    parser.add_argument("--seed", type=int, default=default("seed"), metavar="K", help=f"seed of every draw (default {default('seed')})")
    parser.add_argument(
        "--probe", default=default("probe"), metavar="SPEC", help=f"the indenter: sphere:r=3mm, cylinder:d=2mm, box:x=4mm,y=4mm,z=2mm (default {default('probe')})")
    parser.add_argument(
        "--target", default=default("target"), choices=list(TARGETS),
        help="what each hold is drawn as: force (default: the forces are the estimator's range whatever the material) or depth (the paper's: forces follow, low ones over-sampled)")
    parser.add_argument(
        "--depth-range", type=number_pair, default=default("depth_range"), metavar="LOW,HIGH", help=f"target depth past the skin point with --target depth, m (default {pair('depth_range')})")
    parser.add_argument("--force-distribution", default=default("force_distribution"), choices=list(FORCE_DISTRIBUTIONS), help="target force law (default loguniform: low forces over-sampled)")
    parser.add_argument("--force-range", type=number_pair, default=default("force_range"), metavar="LOW,HIGH", help=f"target force along the approach, N (default {pair('force_range')})")
    parser.add_argument("--max-tilt", type=number, metavar="DEG", help=f"largest angle between the approach and the skin normal (default {default('max_tilt_deg'):g}; not with --regime stage)")
    parser.add_argument("--regime", choices=list(REGIMES), default=default("regime"),
                        help="gantry (default, the paper's: anywhere on the skin, tilted approaches) or stage (straight down along -z on the skin that "
                        "faces up, as a pressing stage over a strip or pad; with --target depth for a stage that sets its travel)")
    parser.add_argument("--stage-x-range", type=number_pair, metavar="LOW,HIGH", help="where a stage's presses land along x, m in the sensor frame (default: the whole skin)")
    parser.add_argument("--stage-y-range", type=number_pair, metavar="LOW,HIGH", help="where a stage's presses land along y, m (default: the whole skin)")
    parser.add_argument("--speed-range", type=number_pair, default=default("speed_range"), metavar="LOW,HIGH", help=f"approach and retract speed, m/s (default {pair('speed_range')})")
    parser.add_argument("--hold-range", type=number_pair, default=default("hold_range"), metavar="LOW,HIGH", help=f"hold duration, s (default {pair('hold_range')})")
    parser.add_argument("--gap-range", type=number_pair, default=default("gap_range"), metavar="LOW,HIGH", help=f"no-contact time before each event, s (default {pair('gap_range')})")
    parser.add_argument("--max-depth", type=number, default=default("max_depth"), metavar="M", help=f"deepest approach past the skin point, m (default {default('max_depth'):g})")
    parser.add_argument(
        "--max-depth-fraction", type=number, default=default("max_depth_fraction"), metavar="F",
        help=f"deepest approach as a fraction of the elastomer's thickness along it (default {default('max_depth_fraction'):g})")
    parser.add_argument("--rate", type=number, default=default("rate_hz"), metavar="HZ", help=f"sample rate (default {default('rate_hz'):g})")
    parser.add_argument("--rays", type=int, default=default("num_rays"), metavar="N", help=f"rays per receptive field (default {default('num_rays')})")
    parser.add_argument("--noise", type=number, metavar="PA", help="barometer RMS noise in Pa (default: the part's)")
    parser.add_argument("--gain-spread", type=number, default=0.0, metavar="S", help="std. dev. of the channel gains around 1, drawn per dataset (default 0)")
    parser.add_argument("--offset-spread", type=number, default=0.0, metavar="PA", help="std. dev. of the channel offsets, Pa (default 0)")
    parser.add_argument("--position-jitter", type=number, default=0.0, metavar="M", help="std. dev. of each barometer's position per axis, m (default 0)")
    parser.add_argument("--shard-rows", type=int, default=default("shard_rows"), metavar="N", help=f"rows per Parquet shard (default {default('shard_rows')})")
    parser.add_argument("--test-fraction", type=number, default=default("test_fraction"), metavar="F", help=f"fraction of the event blocks held out for testing (default {default('test_fraction'):g})")
    parser.add_argument("--ray", metavar="ADDRESS", help="send the pose batches to a Ray cluster as tasks: 'auto' (the running cluster) or its address (default: this process, every local JAX device)")
    parser.add_argument(
        "-o", "--output", required=True, type=Path, metavar="DIR", help="the dataset folder (new or empty; the same command resumes its interrupted run)")
    parser.add_argument("--no-plots", action="store_true", help="skip the plots")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    return parser


def run(args) -> None:
    from .._errors import HydrotactError
    from ..datasets import DatasetConfig, generate_dataset, load_dataset

    if args.material is not None and args.modulus is not None:
        raise HydrotactError("--modulus: give either --material or --modulus, not both")
    if args.regime == "stage" and args.max_tilt is not None:
        raise HydrotactError("--max-tilt: a stage presses straight down (--regime stage); leave it out")
    tilt = {} if args.max_tilt is None else {"max_tilt_deg": args.max_tilt}
    config = DatasetConfig(
        events=args.events, seed=args.seed, probe=args.probe, target=args.target, depth_range=args.depth_range, force_distribution=args.force_distribution, force_range=args.force_range,
        **tilt, regime=args.regime, stage_x_range=args.stage_x_range, stage_y_range=args.stage_y_range, speed_range=args.speed_range, hold_range=args.hold_range, gap_range=args.gap_range,
        max_depth=args.max_depth, max_depth_fraction=args.max_depth_fraction,
        rate_hz=args.rate, num_rays=args.rays, noise_rms=args.noise, gain_spread=args.gain_spread, offset_spread=args.offset_spread,
        position_jitter=args.position_jitter, randomise_material=args.randomise_material, shard_rows=args.shard_rows, test_fraction=args.test_fraction,
    )
    manifest = generate_dataset(
        args.sensor, args.output, material=args.material, modulus=args.modulus,
        config=config, ray_address=args.ray, progress=not args.json,
    )
    plots = []
    if not args.no_plots:
        from ..viz import plot_dataset

        plots = [str(path) for path in plot_dataset(load_dataset(args.output), args.output)]
    stats = manifest["statistics"]
    split = manifest["split"]
    report = {
        "dataset": str(args.output),
        "status": manifest["status"],
        "sensor": manifest["sensor"]["name"],
        "events": manifest["num_events"],
        "rows": manifest["num_rows"],
        "duration_min": manifest["duration_s"] / 60.0,
        "distinct_poses": manifest["num_distinct_poses"],
        "rounds": manifest["num_rounds"],
        "shards": len(manifest["shards"]),
        "train_rows": sum(b - a for a, b in split["train"]),
        "test_rows": sum(b - a for a, b in split["test"]),
        "contact_fraction": stats["contact_fraction"],
        "events_short_of_target": stats["events_short_of_target"],
        "channel_std_kPa": ", ".join(f"{name} {1e-3 * s:.2f}" for name, s in zip(manifest["channels"], stats["channel_std_Pa"])),
        "published_std_kPa": "3-9 (real sensors, the barometric estimation paper)",
        "elapsed_s": manifest["elapsed_s"],
        "plots": ", ".join(plots) or "none",
    }
    print_report(f"dataset of {manifest['sensor']['name']}", report, args.json)
