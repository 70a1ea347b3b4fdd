"""Solve a mesh's strain field and report on it: sizes, timings, residual, ranges."""

import time
import warnings

import jax
import numpy as np

from .._defaults import DEFAULT_MODULUS
from .._errors import HydrotactError, HydrotactWarning
from ..mesh import TetMesh
from ._distance import calc_distance_field
from ._kinds import StrainFieldKind
from ._solve import make_laplace_problem, solve_strain

PLAUSIBLE_MODULUS_PA = (1e3, 1e8)
"""Hydroelastic moduli of real elastomer skins lie well inside this range (gels of a
few kPa to stiff rubbers of tens of MPa): a modulus outside it draws a warning."""


def check_modulus(modulus, what: str = "--modulus", warn: bool = True) -> float:
    """The modulus as a float: refused unless a positive, finite pressure in Pa; with
    `warn`, a :class:`HydrotactWarning` outside :data:`PLAUSIBLE_MODULUS_PA` (a unit slip)."""
    try:
        modulus = float(modulus)
    except (TypeError, ValueError):
        raise HydrotactError(f"{what}: the modulus must be a positive pressure in Pa, got {modulus!r}") from None
    if not np.isfinite(modulus) or modulus <= 0:
        raise HydrotactError(f"{what}: the modulus must be a positive pressure in Pa, got {modulus:g}")
    low, high = PLAUSIBLE_MODULUS_PA
    if warn and not low <= modulus <= high:
        hint = "kPa or MPa meant? it takes Pa: 1e5 is 100 kPa" if modulus < low else "is it in Pa? 1e6 is 1 MPa"
        warnings.warn(HydrotactWarning(f"{what}: {modulus:g} Pa is outside the moduli of elastomer skins, {low:g}-{high:g} Pa ({hint})"), stacklevel=2)
    return modulus


def solve_field_report(
    mesh: TetMesh,
    *,
    kind: StrainFieldKind | str = StrainFieldKind.LAPLACE,
    modulus: float = DEFAULT_MODULUS,
    core_depth: float | None = None,
    source: str | None = None,
) -> tuple[np.ndarray, dict]:
    """Solve the strain field of `mesh` and report on it.

    `kind` is "laplace" (the P1 Laplace solve, e = 0 on the free skin and 1 on the core;
    `core_depth` also fixes e = 1 at vertices at least that far below the skin) or
    "distance" (Drake's distance field). `modulus` (Pa) only scales the reported
    pressures, p = E e.

    **Returns:** (strain at the vertices (num_vertices,), summary dict with sizes,
    timings, residual and the strain and pressure ranges; timings exclude compilation).
    """
    kind = StrainFieldKind.parse(kind, "field kind")
    modulus = check_modulus(modulus, "modulus", warn=False)
    summary = {"kind": str(kind), "num_tets": mesh.num_tets, "num_vertices": mesh.num_vertices, "modulus_Pa": modulus}
    if kind == StrainFieldKind.LAPLACE:
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
