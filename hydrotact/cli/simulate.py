"""`hydrotact simulate`: simulate a sensor along a probe trajectory; write a barometer log."""

from pathlib import Path

from .._defaults import DEFAULT_MODULUS
from ._arguments import MODULUS_HELP, number
from ._output import print_report


def add_parser(subparsers):
    parser = subparsers.add_parser("simulate", help="simulate a sensor along a probe trajectory; write a barometer log")
    parser.add_argument("--sensor", required=True, metavar="S", help="a built-in sensor (pad5x5, sphere8, ellipsoid8) or a sensor JSON file")
    parser.add_argument("--probe", required=True, metavar="SPEC", help="cylinder:d=2mm[,length=10mm], sphere:r=3mm or plane")
    parser.add_argument("--trajectory", required=True, type=Path, metavar="TRAJ.csv", help="CSV with columns time (s), x, y, z (probe tip, --units) and optionally rx, ry, rz (rad)")
    parser.add_argument("--units", default="m", choices=["m", "mm", "cm", "um"], help="length unit of the trajectory's x, y, z (default m)")
    parser.add_argument("--modulus", type=number, default=DEFAULT_MODULUS, metavar="E", help=MODULUS_HELP)
    parser.add_argument("--material", type=Path, metavar="MATERIAL.json", help="a viscoelastic material (Prony series; e.g. from hydrotact fit); overrides --modulus")
    parser.add_argument("--barometer", action="store_true", help="write absolute barometer readings (the sensor's part: ambient, LSB, noise, rate) instead of elastomer pressures")
    parser.add_argument("--seed", type=int, default=0, help="seed of the barometer noise and channel spreads (default 0)")
    parser.add_argument("--noise", type=number, metavar="PA", help="barometer RMS noise in Pa (default: the part's)")
    parser.add_argument("--gain-spread", type=number, default=0.0, metavar="S", help="std. dev. of the channel gains around 1 (default 0)")
    parser.add_argument("--offset-spread", type=number, default=0.0, metavar="PA", help="std. dev. of the channel offsets in Pa (default 0)")
    parser.add_argument("--force-noise", type=number, default=0.0, metavar="N", help="load-cell RMS noise added to fx, fy, fz in N (default 0)")
    parser.add_argument("--field", default="laplace", choices=["laplace", "distance"], help="the sensor's strain field")
    parser.add_argument("--rays", type=int, default=64, metavar="N", help="rays per taxel receptive field (default 64)")
    parser.add_argument("-o", "--output", required=True, type=Path, metavar="LOG.parquet", help="the log to write (Parquet)")
    parser.add_argument("--png", type=Path, metavar="LOG.png", help="plot the simulated traces")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    return parser


def run(args) -> None:
    from .._simulate_job import run_simulate  # moving into hydrotact.sim

    report = run_simulate(
        args.sensor, args.probe, args.trajectory, args.output, modulus=args.modulus, material=args.material, barometer=args.barometer,
        seed=args.seed, noise_rms=args.noise, gain_spread=args.gain_spread, offset_spread=args.offset_spread, force_noise=args.force_noise, field=args.field,
        num_rays=args.rays, units=args.units, png=args.png, progress=not args.json,
    )
    print_report(f"simulated log of {report['sensor']}", report, args.json)
