"""`hydrotact mesh`: mesh a sensor or a closed surface; report counts and quality."""

from pathlib import Path

from ._arguments import add_source_arguments
from ._output import print_report, status


def add_parser(subparsers):
    parser = subparsers.add_parser("mesh", help="mesh a sensor or a closed surface; report counts and quality")
    add_source_arguments(parser, "SENSOR_OR_SURFACE_FILE")
    parser.add_argument("-o", "--output", type=Path, metavar="MESH.vtu", help="write the mesh (VTK XML, with tags)")
    parser.add_argument("--vtk", type=Path, metavar="MESH.vtk", help="write the mesh as legacy ASCII VTK (loads in Drake)")
    parser.add_argument("--png", type=Path, metavar="MESH.png", help="render the mesh")
    return parser


def run(args) -> None:
    from .._files import check_output
    from ..mesh import MESH_SUFFIXES, calc_mesh_quality, load_tet_mesh, write_mesh

    for path, suffixes in ((args.output, MESH_SUFFIXES), (args.vtk, (".vtk",)), (args.png, (".png",))):
        if path is not None:
            check_output(path, suffixes=suffixes)
    with status(f"meshing {args.source}"):
        mesh = load_tet_mesh(args.source, edge_length=args.edge_length, units=args.units, core_plane_z=args.core_plane)
    report = calc_mesh_quality(mesh)
    if args.output:
        write_mesh(mesh, args.output)
    if args.vtk:
        write_mesh(mesh, args.vtk)
    if args.png:
        from ..viz import render_mesh

        render_mesh(mesh, args.png, title=args.source)
    print_report(f"mesh of {args.source}", report, args.json)
