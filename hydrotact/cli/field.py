"""`hydrotact field`: solve the strain field of a sensor or mesh; report on it."""

from pathlib import Path

from .._defaults import DEFAULT_MODULUS
from ._arguments import MODULUS_HELP, add_source_arguments, number
from ._output import print_report, status


def add_parser(subparsers):
    parser = subparsers.add_parser("field", help="solve the strain field of a sensor or mesh; report on it")
    add_source_arguments(parser, "SENSOR_OR_MESH")
    parser.add_argument("--modulus", type=number, default=DEFAULT_MODULUS, metavar="E", help=MODULUS_HELP)
    parser.add_argument("--kind", default="laplace", choices=["laplace", "distance"], help="Laplace strain field, or Drake's distance field")
    parser.add_argument("--core-depth", type=number, metavar="D", help="also fix e = 1 at vertices at least D metres below the free skin")
    parser.add_argument("-o", "--output", type=Path, metavar="FIELD.vtu", help="write the mesh with strain and pressure")
    parser.add_argument("--png", type=Path, metavar="FIELD.png", help="render the pressure field")
    return parser


def run(args) -> None:
    from .._files import check_output
    from ..field import check_modulus, solve_field_report
    from ..mesh import MESH_SUFFIXES, load_tet_mesh, write_mesh

    check_modulus(args.modulus)
    for path, suffixes in ((args.output, MESH_SUFFIXES), (args.png, (".png",))):
        if path is not None:
            check_output(path, suffixes=suffixes)
    with status(f"meshing {args.source}"):
        mesh = load_tet_mesh(args.source, edge_length=args.edge_length, units=args.units, core_plane_z=args.core_plane)
    with status(f"solving the {args.kind} strain field ({mesh.num_tets} tets; the first solve compiles)"):
        strain, report = solve_field_report(mesh, kind=args.kind, modulus=args.modulus, core_depth=args.core_depth, source=args.source)
    if args.output:
        write_mesh(mesh, args.output, point_data={"strain": strain, "pressure_Pa": args.modulus * strain})
    if args.png:
        from ..viz import render_field

        render_field(mesh, args.modulus * strain, args.png, label="pressure [Pa]", title=f"{args.source}: {args.kind} field")
    print_report(f"{args.kind} field of {args.source}", report, args.json)
