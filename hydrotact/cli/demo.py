"""`hydrotact demo`: the main job on built-in data (simulate a pad5x5 log with a known
viscoelastic material, fit it back)."""

from pathlib import Path


def add_parser(subparsers):
    parser = subparsers.add_parser("demo", help="the main job on built-in data: simulate a pad5x5 log with a known viscoelastic material, fit it back; results and pictures in out/")
    parser.add_argument("-o", "--output", type=Path, default=Path("out"), metavar="DIR")
    parser.add_argument("--smoke", action="store_true", help="the same job at test-suite size (two presses, two Prony terms)")
    return parser


def run(args) -> None:
    from .._demo_job import run_demo  # moving into hydrotact.sim

    summary = run_demo(args.output, smoke=args.smoke)
    print(f"hydrotact demo: results in {args.output}/")
    for path in summary["files"].values():
        print(f"  {path}")
    print(f"  {args.output / 'summary.json'}")
