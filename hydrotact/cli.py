"""The `hydrotact` command: thin wrappers over the library.

Every user error ends in one line, `hydrotact: error: ...`, naming the file, field or
value at fault, and exit status 2; never a traceback.
"""

import argparse
import json
import sys
from pathlib import Path

from . import __version__
from ._errors import HydrotactError


def _length(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hydrotact",
        description="Differentiable simulation and system identification for barometric tactile sensors.",
    )
    parser.add_argument("--version", action="version", version=f"hydrotact {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def source_arguments(sub, what):
        sub.add_argument("source", metavar=what, help="a built-in sensor (pad5x5, sphere8, ellipsoid8) or a file")
        sub.add_argument("--edge-length", type=_length, metavar="L", help="target tet edge length in metres (sensors, surfaces)")
        sub.add_argument("--units", default="m", choices=["m", "mm", "cm", "um"], help="length unit of a surface file (default m)")
        sub.add_argument("--core-plane", type=_length, metavar="Z", help="the core (bonded) faces lie on the plane z = Z, in --units (default: the lowest z)")
        sub.add_argument("--json", action="store_true", help="print the report as JSON")

    mesh = commands.add_parser("mesh", help="mesh a sensor or a closed surface; report counts and quality")
    source_arguments(mesh, "SENSOR_OR_SURFACE_FILE")
    mesh.add_argument("-o", "--output", type=Path, metavar="MESH.vtu", help="write the mesh (VTK XML, with tags)")
    mesh.add_argument("--vtk", type=Path, metavar="MESH.vtk", help="write the mesh as legacy ASCII VTK (loads in Drake)")
    mesh.add_argument("--png", type=Path, metavar="MESH.png", help="render the mesh")

    field = commands.add_parser("field", help="solve the strain field of a sensor or mesh; report on it")
    source_arguments(field, "SENSOR_OR_MESH")
    field.add_argument("--modulus", type=_length, default=1e5, metavar="E", help="hydroelastic modulus in Pa (default 1e5)")
    field.add_argument("--kind", default="laplace", choices=["laplace", "distance"], help="Laplace strain field, or Drake's distance field")
    field.add_argument("--core-depth", type=_length, metavar="D", help="also fix e = 1 at vertices at least D metres below the free skin")
    field.add_argument("-o", "--output", type=Path, metavar="FIELD.vtu", help="write the mesh with strain and pressure")
    field.add_argument("--png", type=Path, metavar="FIELD.png", help="render the pressure field")

    contact = commands.add_parser("contact", help="press a probe into a sensor; report the contact surface and wrench")
    which = contact.add_mutually_exclusive_group(required=True)
    which.add_argument("--sensor", choices=["pad5x5", "sphere8", "ellipsoid8"], help="a built-in sensor")
    which.add_argument("--mesh", metavar="FILE", help="a tet mesh (.vtu/.vtk) or closed surface file")
    contact.add_argument("--field", default="laplace", choices=["laplace", "distance"], help="the sensor's strain field")
    contact.add_argument("--modulus", type=_length, default=1e5, metavar="E", help="hydroelastic modulus in Pa (default 1e5)")
    contact.add_argument("--probe", required=True, metavar="SPEC", help="cylinder:d=2mm[,length=10mm], sphere:r=3mm or plane")
    contact.add_argument("--at", required=True, metavar="X,Y,DEPTH", help="tip position over the sensor and depth below its skin (e.g. 0,2.2mm,0.4mm; bare numbers are metres)")
    contact.add_argument("--json", action="store_true", help="print the report as JSON")
    contact.add_argument("--png", type=Path, metavar="CONTACT.png", help="render the contact surface over the sensor")

    simulate = commands.add_parser("simulate", help="simulate a sensor along a probe trajectory; write a barometer log")
    simulate.add_argument("--sensor", required=True, metavar="S", help="a built-in sensor (pad5x5, sphere8, ellipsoid8) or a sensor JSON file")
    simulate.add_argument("--probe", required=True, metavar="SPEC", help="cylinder:d=2mm[,length=10mm], sphere:r=3mm or plane")
    simulate.add_argument("--trajectory", required=True, type=Path, metavar="TRAJ.csv", help="CSV with columns time (s), x, y, z (probe tip, --units) and optionally rx, ry, rz (rad)")
    simulate.add_argument("--units", default="m", choices=["m", "mm", "cm", "um"], help="length unit of the trajectory's x, y, z (default m)")
    simulate.add_argument("--modulus", type=_length, default=1e6, metavar="E", help="hydroelastic modulus in Pa (default 1e6)")
    simulate.add_argument("--material", type=Path, metavar="MATERIAL.json", help="a viscoelastic material (Prony series; e.g. from hydrotact fit); overrides --modulus")
    simulate.add_argument("--barometer", action="store_true", help="write absolute barometer readings (the sensor's part: ambient, LSB, noise, rate) instead of elastomer pressures")
    simulate.add_argument("--seed", type=int, default=0, help="seed of the barometer noise and channel spreads (default 0)")
    simulate.add_argument("--noise", type=_length, metavar="PA", help="barometer RMS noise in Pa (default: the part's)")
    simulate.add_argument("--gain-spread", type=_length, default=0.0, metavar="S", help="std. dev. of the channel gains around 1 (default 0)")
    simulate.add_argument("--offset-spread", type=_length, default=0.0, metavar="PA", help="std. dev. of the channel offsets in Pa (default 0)")
    simulate.add_argument("--force-noise", type=_length, default=0.0, metavar="N", help="load-cell RMS noise added to fx, fy, fz in N (default 0)")
    simulate.add_argument("--field", default="laplace", choices=["laplace", "distance"], help="the sensor's strain field")
    simulate.add_argument("--rays", type=int, default=64, metavar="N", help="rays per taxel receptive field (default 64)")
    simulate.add_argument("-o", "--output", required=True, type=Path, metavar="LOG.parquet", help="the log to write (Parquet)")
    simulate.add_argument("--png", type=Path, metavar="LOG.png", help="plot the simulated traces")
    simulate.add_argument("--json", action="store_true", help="print the report as JSON")

    fit = commands.add_parser("fit", help="fit the elastomer's Prony material (and channel gains and offsets) to barometer logs")
    fit.add_argument("logs", nargs="+", type=Path, metavar="LOG", help="barometer logs (.parquet, or .csv with its .json or a --mapping); several are fitted jointly")
    fit.add_argument("--sensor", metavar="S", help="the sensor spec (built-in name or JSON file); default: the log's own")
    fit.add_argument("--lumped", action="store_true", help="no sensor model: each channel a power law of the indentation column, fitted with the kernel")
    fit.add_argument("--indentation", default="indentation", metavar="COL", help="the indentation column of a --lumped fit (default indentation)")
    fit.add_argument("--mapping", type=Path, metavar="MAP.json", help="column mapping for logs of your own layout")
    fit.add_argument("--terms", default="auto", metavar="N|auto", help="Prony terms, or auto (lowest BIC over 0-4; default)")
    fit.add_argument("--solver", default="lm", choices=["lm", "gn", "dogleg", "bfgs", "lbfgsb"], help="lm (Levenberg-Marquardt, default), gn, dogleg, bfgs or lbfgsb (jaxopt, bounded)")
    fit.add_argument("--tare", action="store_true", help="tare each log on its no-load segments first (drifting, aged sensors)")
    fit.add_argument("--field", choices=["laplace", "distance"], help="full mode: the sensor's strain field (default: the log's, else laplace)")
    fit.add_argument("--rays", type=int, metavar="N", help="full mode: rays per taxel (default: the log's, else 64)")
    fit.add_argument("-o", "--output", required=True, type=Path, metavar="FITDIR", help="folder for material.json, report.json and plots")
    fit.add_argument("--json", action="store_true", help="print the report as JSON")

    demo = commands.add_parser("demo", help="the main job on built-in data: simulate a pad5x5 log with a known viscoelastic material, fit it back; results and pictures in out/")
    demo.add_argument("-o", "--output", type=Path, default=Path("out"), metavar="DIR")
    demo.add_argument("--smoke", action="store_true", help="the same job at test-suite size (two presses, two Prony terms)")
    return parser


def _print_report(title: str, report: dict, as_json: bool) -> None:
    if as_json:
        print(json.dumps(report, indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=title, show_header=False)
    for key, value in report.items():
        if isinstance(value, float):
            value = f"{value:.6g}"
        table.add_row(key, str(value))
    Console().print(table)


def _run(args) -> None:
    import jax

    jax.config.update("jax_enable_x64", True)
    from ._jobs import load_tet_mesh, solve_field

    if args.command == "demo":
        from ._demo_job import run_demo

        summary = run_demo(args.output, smoke=args.smoke)
        print(f"hydrotact demo: results in {args.output}/")
        for path in summary["files"].values():
            print(f"  {path}")
        print(f"  {args.output / 'summary.json'}")
        return

    if args.command == "fit":
        from ._fit_job import print_fit_table, run_fit

        def warn(message):
            print(f"hydrotact: warning: {message}", file=sys.stderr)

        report = run_fit(
            args.logs, args.output, sensor=args.sensor, lumped=args.lumped, indentation=args.indentation, mapping=args.mapping,
            terms=args.terms, solver=args.solver, tare=args.tare, field=args.field, num_rays=args.rays, progress=not args.json, report_warning=warn,
        )
        if args.json:
            print(json.dumps(report, indent=2))
        else:
            print_fit_table(report)
            print(f"hydrotact fit: results in {args.output}/")
            for path in report["files"].values():
                print(f"  {path}")
        return

    from .mesh import calc_mesh_quality, write_mesh

    if args.command == "simulate":
        from ._simulate_job import run_simulate

        report = run_simulate(
            args.sensor, args.probe, args.trajectory, args.output, modulus=args.modulus, material=args.material, barometer=args.barometer,
            seed=args.seed, noise_rms=args.noise, gain_spread=args.gain_spread, offset_spread=args.offset_spread, force_noise=args.force_noise, field=args.field,
            num_rays=args.rays, units=args.units, png=args.png, progress=not args.json,
        )
        _print_report(f"simulated log of {report['sensor']}", report, args.json)
        return

    if args.command == "contact":
        from ._contact_job import run_contact

        source = args.sensor or args.mesh
        mesh = load_tet_mesh(source)
        strain, _ = solve_field(mesh, kind=args.field, modulus=args.modulus, source=source)
        report, surface, probe, X_SP = run_contact(mesh, strain, args.modulus, args.probe, args.at)
        if args.png:
            from .viz import render_contact

            render_contact(mesh, surface, args.png, probe=probe, X_SP=X_SP, title=f"{source}: {args.probe} at {args.at}")
        _print_report(f"contact of {args.probe} with {source}", report, args.json)
        return

    mesh = load_tet_mesh(args.source, edge_length=args.edge_length, units=args.units, core_plane_z=args.core_plane)
    if args.command == "mesh":
        report = calc_mesh_quality(mesh)
        if args.output:
            write_mesh(mesh, args.output)
        if args.vtk:
            write_mesh(mesh, args.vtk)
        if args.png:
            from .viz import render_mesh

            render_mesh(mesh, args.png, title=args.source)
        _print_report(f"mesh of {args.source}", report, args.json)
        return

    strain, report = solve_field(mesh, kind=args.kind, modulus=args.modulus, core_depth=args.core_depth, source=args.source)
    if args.output:
        write_mesh(mesh, args.output, point_data={"strain": strain, "pressure_Pa": args.modulus * strain})
    if args.png:
        from .viz import render_field

        render_field(mesh, args.modulus * strain, args.png, label="pressure [Pa]", title=f"{args.source}: {args.kind} field")
    _print_report(f"{args.kind} field of {args.source}", report, args.json)


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    try:
        _run(args)
    except HydrotactError as error:
        print(f"hydrotact: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("hydrotact: interrupted", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
