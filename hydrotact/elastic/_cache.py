"""Receptive fields of a sensor's elastic barometers, solved once and cached by content
(host).

The fields depend only on the mesh (vertices, tets, tags), nu and the ports; the key is
a digest of exactly those, so an edited mesh or a moved barometer solves again and
anything else reads the file back. Barometers are solved one at a time (one compiled
program serves them all), by CG preconditioned with one multigrid hierarchy
(:mod:`._multigrid`), behind a progress bar; each file is written atomically.
"""

import zipfile
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from .._errors import HydrotactError, where
from .._files import atomic_path, cache_dir, digest
from ..mesh import TetMesh
from ._barometers import ReceptiveFields, calc_receptive_fields, make_barometer_ports
from ._multigrid import make_multigrid_preconditioner
from ._problem import make_elastic_problem

_CACHE_VERSION = "elastic-fields/1"
# CG must bring the reduced system's relative residual this close to its tolerance.
_RESIDUAL_SLACK = 1e3


def _fields_path(key: str) -> Path:
    return cache_dir() / "elastic_fields" / f"{key}.npz"


def _load(path: Path, key: str):
    if not path.is_file():
        return None
    try:
        with path.open("rb") as handle, np.load(handle, allow_pickle=False) as saved:
            if str(saved["key"]) != key:
                return None
            return saved["responses"], int(saved["num_steps"]), float(saved["relative_residual"])
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None


def make_receptive_fields(
    mesh: TetMesh,
    positions_S,
    axes_S,
    port_radii,
    readings,
    poisson_ratio,
    *,
    cache: bool = True,
    progress: bool = False,
    source: str | None = None,
) -> ReceptiveFields:
    """The receptive fields of elastic barometers on `mesh` (host; cached by content).

    **Arguments:** the ports' `positions_S` (B, 3) m, `axes_S` (B, 3), `port_radii`
    (B,) m and `readings` (B,) ("pressure" or "normal_stress"); the elastomer's
    `poisson_ratio`; `cache` reads and writes the cache (HYDROTACT_CACHE_DIR);
    `progress` shows a bar over the barometers; `source` names the sensor in errors.

    **Returns:** :class:`ReceptiveFields` in float64.
    """
    problem = make_elastic_problem(mesh, poisson_ratio, source=source)
    ports = make_barometer_ports(positions_S, axes_S, port_radii, readings)
    arrays = [np.ascontiguousarray(np.asarray(a, dtype=np.float64)).tobytes() for a in (mesh.vertices, ports.positions_S, ports.axes_S, ports.port_radii)]
    integers = [np.ascontiguousarray(np.asarray(a, dtype=np.int64)).tobytes() for a in (mesh.tets, mesh.boundary_faces, mesh.face_tags, ports.reads_normal_stress)]
    key = digest(_CACHE_VERSION, float(problem.poisson_ratio), *arrays, *integers)
    path = _fields_path(key)
    saved = _load(path, key) if cache else None
    if saved is None:
        saved = _solve_fields(problem, ports, progress, source)
        if cache:
            responses, num_steps, relative = saved
            with atomic_path(path, suffix=".npz") as tmp:
                np.savez(tmp, key=np.array(key), responses=responses, num_steps=np.array(num_steps), relative_residual=np.array(relative))
    responses, num_steps, relative = saved
    return ReceptiveFields(
        vertices=jnp.asarray(problem.vertices),
        tets=jnp.asarray(problem.tets),
        tet_nodes=jnp.asarray(problem.tet_nodes),
        responses=jnp.asarray(responses),
        num_steps=jnp.asarray(num_steps),
        relative_residual=jnp.asarray(relative),
    )


def _solve_fields(problem, ports, progress: bool, source):
    from tqdm.auto import tqdm

    rtol = 1e-10
    max_steps = 20 * problem.num_nodes + 1000
    columns, steps, residuals = [], [], []
    count = ports.num_barometers
    bar = tqdm(total=count, desc=f"elastic receptive fields ({problem.num_unknowns} unknowns)", unit="barometer", disable=not progress, leave=False)
    with bar:
        bar.set_postfix_str("building the multigrid hierarchy")
        multigrid = make_multigrid_preconditioner(problem)
        bar.set_postfix_str(f"{multigrid.num_levels} levels")
        for b in range(count):
            one = type(ports)(*(np.asarray(leaf)[b : b + 1] for leaf in (ports.positions_S, ports.axes_S, ports.port_radii, ports.reads_normal_stress)))
            fields = calc_receptive_fields(problem, one, rtol=rtol, max_steps=max_steps, throw=False, multigrid=multigrid)
            relative = float(fields.relative_residual)
            if not (np.isfinite(relative) and relative <= _RESIDUAL_SLACK * rtol):
                raise HydrotactError(
                    f"{where(source)}the elastic receptive field of barometer {b} did not converge: relative residual "
                    f"{relative:.3g} after {int(fields.num_steps)} CG steps (at most {max_steps}); the mesh may have "
                    "degenerate tets, or nu may be too close to 0.5"
                )
            columns.append(np.asarray(fields.responses)[:, 0])
            steps.append(int(fields.num_steps))
            residuals.append(relative)
            bar.update(1)
    return np.stack(columns, axis=1), max(steps), max(residuals)
