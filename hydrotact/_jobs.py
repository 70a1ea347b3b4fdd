"""What the command line runs: the mesh, field and demo jobs, as plain functions."""

import json
import time
from pathlib import Path

import jax
import numpy as np

from ._errors import HydrotactError
from ._files import write_text_atomic
from .field import calc_distance_field, make_laplace_problem, solve_strain
from .mesh import (
    MESH_SUFFIXES,
    SEED_SENSORS,
    SURFACE_SUFFIXES,
    Plane,
    TetMesh,
    calc_mesh_quality,
    load_surface,
    make_seed_mesh,
    read_mesh,
    tetrahedralize,
)
from .mesh._surface import UNIT_SCALES

FIELD_KINDS = ("laplace", "distance")


def load_tet_mesh(
    spec: str,
    *,
    edge_length: float | None = None,
    units: str = "m",
    core_plane_z: float | None = None,
) -> TetMesh:
    """A tet mesh from a seed sensor name, a closed surface file or a mesh file.

    Surfaces are meshed by fTetWild with their core on the plane z = `core_plane_z`
    (default: the lowest z of the surface, where it sits on the PCB).
    """
    if spec in SEED_SENSORS:
        return make_seed_mesh(spec, edge_length)
    path = Path(spec)
    suffix = path.suffix.lower()
    if suffix in MESH_SUFFIXES:
        if edge_length is not None:
            raise HydrotactError(f"{path}: --edge-length applies to sensors and surfaces, not to an existing tet mesh")
        core = None if core_plane_z is None else Plane((0.0, 0.0, core_plane_z), tolerance=1e-9)
        return read_mesh(path, core=core)[0]
    if suffix in SURFACE_SUFFIXES:
        surface = load_surface(path, units)
        lo, hi = surface.bounds
        if edge_length is None:
            edge_length = float(np.linalg.norm(hi - lo)) / 20.0
        z = float(lo[2]) if core_plane_z is None else core_plane_z * UNIT_SCALES[units]
        return tetrahedralize(surface, edge_length, core=Plane((0.0, 0.0, z)), source=str(path))
    if path.exists():
        raise HydrotactError(
            f"{path}: unknown file type {suffix!r}; give a surface ({', '.join(SURFACE_SUFFIXES)}) "
            f"or a tet mesh ({', '.join(MESH_SUFFIXES)})"
        )
    raise HydrotactError(f"{spec}: neither a built-in sensor ({', '.join(SEED_SENSORS)}) nor an existing file")


def solve_field(mesh: TetMesh, *, kind: str = "laplace", modulus: float = 1e5, core_depth: float | None = None, source: str | None = None) -> tuple[np.ndarray, dict]:
    """Solve the strain field of `mesh` and report on it.

    Returns (strain at the vertices, summary dict with sizes, timings, residual and
    the strain and pressure ranges; timings exclude compilation).
    """
    if kind not in FIELD_KINDS:
        raise HydrotactError(f"unknown field kind {kind!r}; use one of {FIELD_KINDS}")
    modulus = float(modulus)
    if not np.isfinite(modulus) or modulus <= 0:
        raise HydrotactError(f"the modulus must be a positive pressure in Pa, got {modulus:g}")
    summary = {"kind": kind, "num_tets": mesh.num_tets, "num_vertices": mesh.num_vertices, "modulus_Pa": modulus}
    if kind == "laplace":
        problem = make_laplace_problem(mesh, core_depth=core_depth, source=source)
        start = time.perf_counter()
        solve_strain(problem).strain.block_until_ready()
        compile_seconds = time.perf_counter() - start
        start = time.perf_counter()
        solution = solve_strain(problem)
        strain = np.asarray(solution.strain.block_until_ready())
        summary.update(
            solve_seconds=time.perf_counter() - start,
            first_call_seconds=compile_seconds,
            cg_iterations=int(solution.num_steps),
            residual_norm=float(solution.relative_residual),
            num_unknowns=problem.num_unknowns,
        )
    else:
        start = time.perf_counter()
        strain = np.asarray(calc_distance_field(mesh, source=source))
        summary.update(solve_seconds=time.perf_counter() - start, residual_norm=None)
    summary.update(
        min_strain=float(strain.min()),
        max_strain=float(strain.max()),
        max_pressure_Pa=float(modulus * strain.max()),
        dtype=str(jax.numpy.asarray(0.0).dtype),
    )
    return strain, summary


def run_demo(out_dir) -> dict:
    """Mesh the three seed sensors, solve their fields, render them; write out_dir/.

    Returns the summary (also written as out_dir/summary.json).
    """
    from rich.progress import Progress

    from .mesh import write_mesh
    from .viz import render_field, render_mesh

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    modulus = 1e5
    summary = {"modulus_Pa": modulus, "sensors": {}}
    with Progress(transient=True) as progress:
        task = progress.add_task("seed sensors", total=3 * len(SEED_SENSORS))
        for name in SEED_SENSORS:
            progress.update(task, description=f"{name}: meshing")
            mesh = make_seed_mesh(name)
            quality = calc_mesh_quality(mesh)
            progress.advance(task)
            progress.update(task, description=f"{name}: solving fields")
            strain, field = solve_field(mesh, kind="laplace", modulus=modulus, source=name)
            distance, distance_summary = solve_field(mesh, kind="distance", modulus=modulus, source=name)
            progress.advance(task)
            progress.update(task, description=f"{name}: rendering")
            files = {
                "mesh_png": out_dir / f"{name}_mesh.png",
                "field_png": out_dir / f"{name}_field.png",
                "distance_png": out_dir / f"{name}_distance_field.png",
                "vtu": out_dir / f"{name}.vtu",
            }
            render_mesh(mesh, files["mesh_png"], title=f"{name}: {mesh.num_tets} tets")
            render_field(mesh, modulus * strain, files["field_png"], label="pressure [Pa]", title=f"{name}: Laplace field, E = {modulus:g} Pa")
            render_field(mesh, modulus * distance, files["distance_png"], label="pressure [Pa]", title=f"{name}: distance field (Drake), E = {modulus:g} Pa")
            write_mesh(mesh, files["vtu"], point_data={"strain": strain, "pressure_Pa": modulus * strain, "distance_strain": distance})
            progress.advance(task)
            summary["sensors"][name] = {
                "quality": quality,
                "laplace_field": field,
                "distance_field": distance_summary,
                "files": {k: str(v) for k, v in files.items()},
            }
    write_text_atomic(out_dir / "summary.json", json.dumps(summary, indent=2) + "\n")
    return summary
