"""Receptive fields of a sensor's elastic barometers, solved once and cached by content
(host).

A barometer's field depends only on the mesh (vertices, tets, tags), nu and its own
port; the key is a digest of exactly those, per barometer, so an edited mesh solves
every barometer again, a moved barometer solves itself alone, and anything else reads
the file back. The built-in sensors' fields at their built-in ports ship with the
package (``python -m hydrotact.elastic._cache --regenerate``; float32, checked against
a SHA-256 checksum on load): a user of sphere8 or ellipsoid8 never waits for them.
Barometers are solved one at a time (one compiled program serves them all), by CG
preconditioned with one multigrid hierarchy (:mod:`._multigrid`), behind a progress
bar; each file is written atomically.
"""

import functools
import json
import sys
import zipfile
from importlib.resources import files
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from .._errors import HydrotactError, where
from .._files import atomic_path, cache_dir, digest, write_text_atomic
from ..mesh import TetMesh
from ._barometers import FieldDerivatives, ReceptiveFields, calc_field_derivatives, calc_receptive_fields, make_barometer_ports
from ._cavity import calc_cavity_fields, find_cavity_faces
from ._multigrid import make_multigrid_preconditioner
from ._problem import make_elastic_problem

_CACHE_VERSION = "elastic-field/2"
# CG must bring the reduced system's relative residual this close to its tolerance.
_RESIDUAL_SLACK = 1e3
_RTOL = 1e-10
_DERIVATIVE_RTOL = 1e-8  # a layout design's linearisation: far below the model's own error
_DATA = files("hydrotact.elastic") / "data"


def _field_path(key: str) -> Path:
    return cache_dir() / "elastic_fields" / f"{key}.npz"


def _load(path: Path, key: str):
    if not path.is_file():
        return None
    try:
        with path.open("rb") as handle, np.load(handle, allow_pickle=False) as saved:
            if str(saved["key"]) != key:
                return None
            return saved["response"], int(saved["num_steps"]), float(saved["relative_residual"])
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None


def _response_digest(response) -> str:
    return digest(np.ascontiguousarray(response, dtype=np.float32).tobytes())


@functools.lru_cache(maxsize=1)
def _shipped_index() -> dict:
    """{key: (file name, index)} of the shipped fields."""
    index = {}
    checksums_file = _DATA / "checksums.json"
    if not checksums_file.is_file():
        return index
    for name in json.loads(checksums_file.read_text()):
        with (_DATA / f"{name}.npz").open("rb") as handle, np.load(handle, allow_pickle=False) as saved:
            for b, key in enumerate(saved["keys"]):
                index[str(key)] = (name, b)
    return index


def _load_shipped(key: str):
    found = _shipped_index().get(key)
    if found is None:
        return None
    name, b = found
    checksums = json.loads((_DATA / "checksums.json").read_text())[name]
    with (_DATA / f"{name}.npz").open("rb") as handle, np.load(handle, allow_pickle=False) as saved:
        response = saved["responses"][b]
        steps, residual = int(saved["num_steps"][b]), float(saved["relative_residual"][b])
    if _response_digest(response) != checksums[b]:
        raise HydrotactError(f"the shipped elastic receptive fields of {name} do not match their checksum: reinstall hydrotact")
    return response.astype(np.float64), steps, residual


def _mesh_key(mesh: TetMesh, poisson_ratio: float) -> str:
    mesh_parts = [np.ascontiguousarray(np.asarray(mesh.vertices, dtype=np.float64)).tobytes()]
    mesh_parts += [np.ascontiguousarray(np.asarray(a, dtype=np.int64)).tobytes() for a in (mesh.tets, mesh.boundary_faces, mesh.face_tags)]
    return digest(_CACHE_VERSION, float(poisson_ratio), *mesh_parts)


def field_keys(mesh: TetMesh, ports, poisson_ratio: float) -> list[str]:
    """The content key of each port's receptive field (host): the mesh, nu, the
    port's position and radius, and its axis where it reads the normal stress."""
    mesh_key = _mesh_key(mesh, poisson_ratio)
    positions, axes, radii = (np.asarray(leaf, dtype=np.float64) for leaf in (ports.positions_S, ports.axes_S, ports.port_radii))
    normal = np.asarray(ports.reads_normal_stress, dtype=bool)
    # A pressure port's field does not depend on its axis: turning it solves nothing.
    return [
        digest(mesh_key, positions[b].tobytes(), radii[b].tobytes(), axes[b].tobytes() if normal[b] else None) for b in range(ports.num_barometers)
    ]


def _cached_solves(mesh, positions_S, axes_S, port_radii, readings, poisson_ratio, cache, progress, source, derivatives):
    """(problem, [(array, CG steps, relative residual)] per barometer): each read from
    the cache (or, for fields, the shipped data) or solved and written there."""
    problem = make_elastic_problem(mesh, poisson_ratio, source=source)
    ports = make_barometer_ports(positions_S, axes_S, port_radii, readings)
    keys = field_keys(mesh, ports, float(problem.poisson_ratio))
    pockets = {}  # barometer -> its pocket's faces, for those reading the sealed air
    mesh_key = _mesh_key(mesh, float(problem.poisson_ratio)) if any(str(r) == "cavity" for r in readings) else None
    for b, reading in enumerate(readings):
        if str(reading) == "cavity":
            try:
                pockets[b] = find_cavity_faces(mesh, np.asarray(positions_S, dtype=np.float64)[b])
            except HydrotactError as error:
                raise HydrotactError(f"{where(source)}barometer {b}: {error}") from None
            keys[b] = digest(mesh_key, "cavity", np.ascontiguousarray(np.sort(np.sort(pockets[b], axis=1), axis=0)).tobytes())
    if derivatives:
        keys = [digest(key, "derivatives") for key in keys]
    saved = [(_load(_field_path(key), key) or (None if derivatives else _load_shipped(key))) if cache else None for key in keys]
    missing = [b for b, found in enumerate(saved) if found is None]
    if missing:
        solved = _solve_fields(problem, ports, missing, progress, source, derivatives=derivatives, pockets=pockets)
        for b, found in zip(missing, solved, strict=True):
            saved[b] = found
            if cache:
                response, num_steps, relative = found
                with atomic_path(_field_path(keys[b]), suffix=".npz") as tmp:
                    np.savez(tmp, key=np.array(keys[b]), response=response, num_steps=np.array(num_steps), relative_residual=np.array(relative))
    return problem, saved


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
    """The receptive fields of elastic barometers on `mesh` (host; cached by content,
    per barometer).

    **Arguments:** the ports' `positions_S` (B, 3) m, `axes_S` (B, 3), `port_radii`
    (B,) m and `readings` (B,) ("pressure" or "normal_stress"); the elastomer's
    `poisson_ratio`; `cache` reads and writes the cache (HYDROTACT_CACHE_DIR) and reads
    the shipped fields; `progress` shows a bar over the barometers to solve; `source`
    names the sensor in errors.

    **Returns:** :class:`ReceptiveFields` in float64.
    """
    problem, saved = _cached_solves(mesh, positions_S, axes_S, port_radii, readings, poisson_ratio, cache, progress, source, derivatives=False)
    return ReceptiveFields(
        vertices=jnp.asarray(problem.vertices),
        tets=jnp.asarray(problem.tets),
        tet_nodes=jnp.asarray(problem.tet_nodes),
        responses=jnp.asarray(np.stack([found[0] for found in saved], axis=1)),
        num_steps=jnp.asarray(max(found[1] for found in saved)),
        relative_residual=jnp.asarray(max(found[2] for found in saved)),
    )


def make_field_derivatives(
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
) -> FieldDerivatives:
    """The derivatives of elastic barometers' receptive fields along their ports'
    positions and axes (host; cached by content, per barometer, beside the fields;
    :func:`hydrotact.elastic.calc_field_derivatives`). Arguments as
    :func:`make_receptive_fields`'s."""
    _, saved = _cached_solves(mesh, positions_S, axes_S, port_radii, readings, poisson_ratio, cache, progress, source, derivatives=True)
    stacked = np.stack([found[0] for found in saved], axis=1)  # (num_nodes, B, 3, 6)
    return FieldDerivatives(
        positions=jnp.asarray(stacked[..., :3]),
        axes=jnp.asarray(stacked[..., 3:]),
        num_steps=jnp.asarray(max(found[1] for found in saved)),
        relative_residual=jnp.asarray(max(found[2] for found in saved)),
    )


def _solve_fields(problem, ports, barometers, progress: bool, source, derivatives: bool = False, pockets=None):
    """[(response (num_nodes, 3), CG steps, relative residual)] of each of `barometers`;
    with `derivatives`, the response's derivatives along the port's position and axis
    (num_nodes, 3, 6) instead (the axis' zero for a pressure port). A barometer in
    `pockets` ({index: its pocket's faces}) reads its pocket's air
    (:func:`calc_cavity_fields`); its field does not move with its port (zero
    derivatives: the pocket is the cast's)."""
    from tqdm.auto import tqdm

    with jax.enable_x64(True):  # a 1e-10 residual is out of float32's reach, whatever the caller's precision
        return _solve_fields_x64(problem, ports, barometers, progress, source, tqdm, derivatives, pockets or {})


def _solve_fields_x64(problem, ports, barometers, progress, source, tqdm, derivatives, pockets):
    max_steps = 20 * problem.num_nodes + 1000
    rtol = _DERIVATIVE_RTOL if derivatives else _RTOL
    what = "derivatives of elastic receptive fields" if derivatives else "elastic receptive fields"
    solved = []
    bar = tqdm(total=len(barometers), desc=f"{what} ({problem.num_unknowns} unknowns)", unit="barometer", disable=not progress, leave=False)
    with bar:
        bar.set_postfix_str("building the multigrid hierarchy")
        multigrid = make_multigrid_preconditioner(problem)
        bar.set_postfix_str(f"{multigrid.num_levels} levels")
        for b in barometers:
            one = type(ports)(*(np.asarray(leaf)[b : b + 1] for leaf in (ports.positions_S, ports.axes_S, ports.port_radii, ports.reads_normal_stress)))
            if b in pockets and derivatives:
                solved.append((np.zeros((problem.num_nodes, 3, 6)), 0, 0.0))
                bar.update(1)
                continue
            if b in pockets:
                found = calc_cavity_fields(problem, [pockets[b]], rtol=rtol, max_steps=max_steps, throw=False, multigrid=multigrid).fields
                response = np.asarray(found.responses)[:, 0]
            elif derivatives:
                found = calc_field_derivatives(problem, one, rtol=rtol, max_steps=max_steps, throw=False, multigrid=multigrid)
                response = np.concatenate([np.asarray(found.positions)[:, 0], np.asarray(found.axes)[:, 0]], axis=-1)
            else:
                found = calc_receptive_fields(problem, one, rtol=rtol, max_steps=max_steps, throw=False, multigrid=multigrid)
                response = np.asarray(found.responses)[:, 0]
            relative = float(found.relative_residual)
            if not (np.isfinite(relative) and relative <= _RESIDUAL_SLACK * rtol):
                raise HydrotactError(
                    f"{where(source)}the {what[:-1] if not derivatives else what} of barometer {b} did not converge: relative residual "
                    f"{relative:.3g} after {int(found.num_steps)} CG steps (at most {max_steps}); the mesh may have "
                    "degenerate tets, or nu may be too close to 0.5"
                )
            solved.append((response, int(found.num_steps), relative))
            bar.update(1)
    return solved


def regenerate_shipped_fields(names=("sphere8", "ellipsoid8")) -> None:
    """Solve the built-in curved sensors' elastic fields at their built-in ports (the
    spec's positions and axes, the default port radius, reading the pressure) and write
    them as package data."""
    from ..sensors import load_sensor
    from ._barometers import DEFAULT_PORT_RADIUS

    checksums = {}
    for name in names:
        spec = load_sensor(name)
        mesh = spec.make_mesh()
        count = len(spec.taxel_names)
        radii, readings = np.full(count, DEFAULT_PORT_RADIUS), ["pressure"] * count
        problem = make_elastic_problem(mesh, spec.poisson_ratio, source=name)
        ports = make_barometer_ports(spec.taxel_positions_S, spec.taxel_axes_S, radii, readings)
        keys = field_keys(mesh, ports, float(problem.poisson_ratio))
        solved = _solve_fields(problem, ports, list(range(count)), True, name)
        responses = np.stack([response for response, _, _ in solved]).astype(np.float32)
        with atomic_path(_DATA / f"{name}.npz") as tmp:
            np.savez_compressed(
                tmp,
                keys=np.array(keys),
                responses=responses,
                num_steps=np.array([steps for _, steps, _ in solved]),
                relative_residual=np.array([residual for _, _, residual in solved]),
            )
        checksums[name] = [_response_digest(response) for response in responses]
        print(f"{name}: {count} barometers, {responses.shape[1]} nodes, at most {max(s for _, s, _ in solved)} CG steps")
    write_text_atomic(_DATA / "checksums.json", json.dumps(checksums, indent=2) + "\n")


if __name__ == "__main__":
    if sys.argv[1:] != ["--regenerate"]:
        sys.exit("usage: python -m hydrotact.elastic._cache --regenerate")
    regenerate_shipped_fields()
