"""`hydrotact mesh`: mesh a sensor, a closed surface or a mould's cavity; report counts and quality."""

from pathlib import Path

from .._choices import BOARD_FACES
from ._arguments import add_source_arguments
from ._output import print_report, status


def add_parser(subparsers):
    parser = subparsers.add_parser("mesh", help="mesh a sensor or a closed surface; report counts and quality")
    add_source_arguments(parser, "SENSOR_OR_SURFACE_FILE", optional=True)
    parser.add_argument("--mould", action="append", type=Path, metavar="FILE", help="mesh the cavity of this mould (repeat for each part of a closed mould, assembled as exported), in --units")
    parser.add_argument("--board", choices=BOARD_FACES, help="with --mould: the cavity's side that lies on the board, towards the mould's -x ... +z (default zmin)")
    parser.add_argument("-o", "--output", type=Path, metavar="MESH.vtu", help="write the mesh (VTK XML, with tags)")
    parser.add_argument("--vtk", type=Path, metavar="MESH.vtk", help="write the mesh as legacy ASCII VTK (loads in Drake)")
    parser.add_argument("--png", type=Path, metavar="MESH.png", help="render the mesh")
    return parser


def run(args) -> None:
    from .._errors import HydrotactError
    from .._files import check_output
    from ..mesh import MESH_SUFFIXES, calc_mesh_quality, load_tet_mesh, write_mesh

    if (args.source is None) == (not args.mould):
        raise HydrotactError("give a sensor or surface file, or --mould FILE, not both" if args.mould else "give a sensor or surface file to mesh, or --mould FILE")
    if args.board is not None and not args.mould:
        raise HydrotactError("--board applies to --mould (the side of the mould's cavity on the board)")
    source = [str(path) for path in args.mould] if args.mould else args.source
    name = f"the cavity of {', '.join(source)}" if args.mould else args.source

    for path, suffixes in ((args.output, MESH_SUFFIXES), (args.vtk, (".vtk",)), (args.png, (".png",))):
        if path is not None:
            check_output(path, suffixes=suffixes)
    with status(f"meshing {name}"):
        mesh = load_tet_mesh(source, edge_length=args.edge_length, units=args.units, core_plane_z=args.core_plane, board=args.board or "zmin")
    report = calc_mesh_quality(mesh)
    if args.output:
        write_mesh(mesh, args.output)
    if args.vtk:
        write_mesh(mesh, args.vtk)
    if args.png:
        from ..viz import render_mesh

        render_mesh(mesh, args.png, title=name)
    print_report(f"mesh of {name}", report, args.json)
