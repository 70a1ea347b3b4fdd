"""`hydrotact contact`: press a probe into a sensor; report the contact surface and wrench."""

from pathlib import Path

from .._defaults import DEFAULT_MODULUS
from ._arguments import MODULUS_HELP, number
from ._output import print_report, status


def add_parser(subparsers):
    parser = subparsers.add_parser("contact", help="press a probe into a sensor; report the contact surface and wrench")
    which = parser.add_mutually_exclusive_group(required=True)
    which.add_argument("--sensor", choices=["pad5x5", "sphere8", "ellipsoid8"], help="a built-in sensor")
    which.add_argument("--mesh", metavar="FILE", help="a tet mesh (.vtu/.vtk) or closed surface file")
    parser.add_argument("--field", default="laplace", choices=["laplace", "distance"], help="the sensor's strain field")
    parser.add_argument("--modulus", type=number, default=DEFAULT_MODULUS, metavar="E", help=MODULUS_HELP)
    parser.add_argument("--probe", required=True, metavar="SPEC", help="cylinder:d=2mm[,length=10mm], sphere:r=3mm or plane")
    parser.add_argument("--at", required=True, metavar="X,Y,DEPTH", help="tip position over the sensor and depth below its skin (e.g. 0,2.2mm,0.4mm; bare numbers are metres)")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.add_argument("--png", type=Path, metavar="CONTACT.png", help="render the contact surface over the sensor")
    return parser


def run(args) -> None:
    from .._files import check_output
    from ..contact import parse_at, parse_probe, press_probe
    from ..field import check_modulus, solve_field_report
    from ..mesh import load_tet_mesh

    if args.png is not None:
        check_output(args.png, suffixes=(".png",))
    check_modulus(args.modulus)
    parse_probe(args.probe)  # all refused before the slow part if malformed
    parse_at(args.at)
    source = args.sensor or args.mesh
    with status(f"meshing {source} and solving its {args.field} strain field"):
        mesh = load_tet_mesh(source)
        strain, _ = solve_field_report(mesh, kind=args.field, modulus=args.modulus, source=source)
    with status("pressing the probe (the first contact compiles its kernels: 10-40 s)"):
        report, surface, probe, X_SP = press_probe(mesh, strain, args.modulus, args.probe, args.at)
    print_report(f"contact of {args.probe} with {source}", report, args.json)
    if args.png:
        from ..viz import render_contact

        render_contact(mesh, surface, args.png, probe=probe, X_SP=X_SP, title=f"{source}: {args.probe} at {args.at}")
