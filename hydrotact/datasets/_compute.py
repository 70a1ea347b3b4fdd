"""Unit responses of many poses, on every local JAX device or on a Ray cluster (host).

The expensive, embarrassingly parallel part of a dataset: one
:func:`hydrotact.sim.calc_unit_response` per distinct pose. Both engines give the same
bits for the same poses, because what a pose is computed with depends on the poses
alone, never on the number of devices or workers:

- a batch is cut into slices of `CHUNK` poses (the last one padded with its last
  pose), and every call computes one slice per device: one compiled program of one
  shape on one device, four, or a Ray worker;
- each slice starts on a rung of one ladder of buffer sizes (:data:`CAPACITY_LADDER`,
  with every rung holding all of the probe's triangles): the bottom one, or the one
  that holds what its poses are predicted to need (`needs`: the dataset's march
  predicts each approach sample's needs from the event's samples before it, and a
  hold's from the approach sample just past it); while any of its poses overflows,
  it is computed again on the lowest rung that holds what its overflowing poses
  needed (past the top rung, the buffers grown to those needs,
  :meth:`hydrotact._buffers.AbstractCapacity.grown_to`). So a slice's capacity is a
  function of its poses and their predictions, and a slice of easy poses is not made
  to pay for a hard one elsewhere in the batch (a tilted press near the base of a
  curved sensor can need 20x the buffers of a press on top). A pose's cost is its
  buffers' size, not what it touches (benchmarks/HISTORY.md), and the rungs are few,
  each compiled once: per-buffer sizes chosen freely made so many combinations that
  compiling them cost more than the small buffers saved (measured). A longer buffer
  can change a sum in its last bit (reductions over other lengths), never more.

Locally each device gets one slice at a time, all dispatched at once (JAX runs them
concurrently): every device runs the same single-device program. Not `shard_map` over a
device mesh: its partitioned program is fused differently from the one-device program,
and the centre of pressure then differed in the last bit with four host devices
(measured), so the shards were not byte-identical. On Ray (`ray_address`), a batch's
slices are sent in blocks as Ray tasks, each run by the local engine of its worker.
"""

import dataclasses
import functools

import equinox as eqx
import jax
import numpy as np

from ..contact import make_pose, map_over_poses
from ..sim import SimCapacity, UnitResponse, calc_unit_response

CHUNK = 64
"""Poses per slice: per device per call (a multiple of the contact stage's CPU pose group)."""

RAY_SLICES = 4
"""The most slices per Ray task (fewer when there are fewer slices than the cluster has CPUs)."""

FULL_CAPACITY = SimCapacity(tets=1024, others=1536, pairs=8192, polygons=2048, taxel_pairs=8192, taxel_pieces=16384)
"""Buffers that hold most presses of a 3 mm sphere on the built-in sensors (measured),
in the proportions such presses fill them: the taxel buffers grow fastest with depth
(at half these taxel sizes they bound nearly every slice above the second rung, with
the contact's buffers a quarter full; benchmarks/HISTORY.md)."""

CAPACITY_LADDER = tuple(SimCapacity(*(size << 2 >> k for size in FULL_CAPACITY.sizes)) for k in range(4, -1, -1))
"""The rungs a slice climbs: FULL_CAPACITY times 1/4 (a press 0.1 mm deep fits), 1/2,
1, 2 and 4 (:func:`_ladder` gives each probe's `others`). A rung costs about twice the
one below it (measured: 0.24, 0.50, 1.08 and 1.92 s per slice of 64 poses on the first
four, sphere8, 2-core CPU)."""

_FIELDS = tuple(field.name for field in dataclasses.fields(UnitResponse))


@functools.lru_cache(maxsize=16)
def _probe_ladder(num_faces: int | None) -> tuple[SimCapacity, ...]:
    """CAPACITY_LADDER for a probe of `num_faces` triangles (None: the half-space):
    every rung's `others` buffer (the probe's triangles near the sensor) holds all of
    them, up to the top rung's. That need does not grow with depth as the others do:
    on a curved sensor most of the probe lies inside the sensor's box from first
    contact (a 3 mm sphere of 1280 triangles needed 880-1180 on sphere8 at every
    depth, measured), so on the ladder's proportions it sent every touching slice
    past two rungs, and on the upper rungs it made the dense tet-triangle box test
    up to 4.8x larger than the probe can fill."""
    if num_faces is None:
        return CAPACITY_LADDER
    others = min(num_faces, CAPACITY_LADDER[-1].others)
    return tuple(dataclasses.replace(rung, others=others) for rung in CAPACITY_LADDER)


def _ladder(probe) -> tuple[SimCapacity, ...]:
    faces = getattr(probe, "faces", None)
    return _probe_ladder(None if faces is None else int(faces.shape[0]))


@functools.lru_cache(maxsize=16)
def _kernel(capacity: SimCapacity):
    @eqx.filter_jit
    def kernel(model, probe, rows):
        X_SR = jax.vmap(make_pose)(rows[:, :3], rows[:, 3:])
        return map_over_poses(lambda X: calc_unit_response(model, probe, X, capacity), X_SR)

    return kernel


def _rounded(capacity: SimCapacity) -> SimCapacity:
    """Every buffer rounded up to a power of two: few distinct capacities, so few
    compilations (each new one compiles the kernels again, ~20 s on a laptop CPU)."""
    return capacity.rounded_up()


def _next_capacity(capacity: SimCapacity, needed: np.ndarray, ladder: tuple = CAPACITY_LADDER) -> SimCapacity:
    """Where a slice that overflowed at `capacity` computes next: the lowest rung of
    `ladder` above it that holds `needed` (rows of overflowing poses), else (past the
    top) the buffers grown to those needs."""
    most = np.max(np.reshape(needed, (-1, len(capacity.sizes))), axis=0)
    above = ladder[ladder.index(capacity) + 1 :] if capacity in ladder else ()
    for rung in above:
        if all(int(n) <= size for n, size in zip(most, rung.sizes)):
            return rung
    return _rounded(capacity.grown_to(needed))


def calc_start_rungs(probe, needs: np.ndarray) -> np.ndarray:
    """Per row of `needs` (n, 6), predicted buffer needs (UnitResponse.needed's order),
    the index of the lowest rung of the probe's ladder that holds it (the top rung's
    when none does: the slice then grows past it)."""
    sizes = np.array([rung.sizes for rung in _ladder(probe)])
    fits = np.all(np.asarray(needs)[:, None, :] <= sizes[None], axis=2)
    return np.where(fits.any(axis=1), np.argmax(fits, axis=1), len(sizes) - 1)


def _slices(rows: np.ndarray) -> np.ndarray:
    """(S, CHUNK, ...): the rows cut into slices, the last padded with its last row."""
    count = len(rows)
    index = np.minimum(np.arange(-(-count // CHUNK) * CHUNK), count - 1)
    return rows[index].reshape(-1, CHUNK, *rows.shape[1:])


def compute_slices(model, probe, slices: np.ndarray, num_devices: int | None = None, starts=None) -> dict:
    """Unit responses (a dict of NumPy arrays (S, CHUNK, ...), UnitResponse's fields)
    of the pose slices (S, CHUNK, 6), each slice grown on its own from its rung of the
    probe's ladder (`starts` (S,) rung indices; the bottom one by default) until none
    of its poses overflows, one slice per device at a time."""
    devices = jax.local_devices()[: num_devices or len(jax.local_devices())]
    placed = [(jax.device_put(model, device), jax.device_put(probe, device)) for device in devices]
    count = len(slices)
    ladder = _ladder(probe)
    capacities = [ladder[0]] * count if starts is None else [ladder[int(k)] for k in starts]
    results: list = [None] * count
    pending = list(range(count))
    while pending:
        groups: dict = {}
        for s in pending:
            groups.setdefault(capacities[s], []).append(s)
        pending = []
        for capacity, members in groups.items():
            kernel = _kernel(capacity)
            for start in range(0, len(members), len(devices)):
                batch = members[start : start + len(devices)]
                # One slice per device, dispatched asynchronously: they run at once.
                units = [kernel(*placed[k], jax.device_put(slices[s], devices[k])) for k, s in enumerate(batch)]
                for s, unit in zip(batch, units):
                    arrays = {name: np.asarray(getattr(unit, name)) for name in _FIELDS}
                    overflow = arrays["did_overflow"]
                    if overflow.any():
                        capacities[s] = _next_capacity(capacity, arrays["needed"][overflow], ladder)
                        pending.append(s)
                    else:
                        results[s] = arrays
    return {name: np.stack([result[name] for result in results]) for name in _FIELDS}


def _slice_starts(probe, needs):
    """Per slice of rows, the rung that holds every row's predicted `needs`
    (None without a prediction: every slice from the bottom rung)."""
    if needs is None:
        return None
    return _slices(calc_start_rungs(probe, needs)).max(axis=1)


def compute_block(model, probe, rows: np.ndarray, num_devices: int | None = None, needs=None) -> dict:
    """Unit responses (a dict of NumPy arrays, UnitResponse's fields, leading axis n)
    of pose `rows` (n, 6), on `num_devices` local devices (all by default); `needs`
    (n, 6), the buffers each pose is predicted to need, chooses each slice's first
    rung (a prediction that errs low costs a climb, never a wrong answer)."""
    rows = np.asarray(rows, dtype=np.float64)
    result = compute_slices(model, probe, _slices(rows), num_devices, _slice_starts(probe, needs))
    return {name: values.reshape(-1, *values.shape[2:])[: len(rows)] for name, values in result.items()}


def _ray_task(model, probe, slices, starts, x64):
    jax.config.update("jax_enable_x64", bool(x64))
    return compute_slices(model, probe, slices, starts=starts)


class PoseEngine:
    """Computes unit responses of pose batches, in-process or on Ray (see the module).

    `ray_address`: None (in-process, every local device), "auto" (the running
    cluster) or a cluster's address."""

    def __init__(self, model, probe, ray_address: str | None = None):
        self.model, self.probe = model, probe
        self.ray_address = ray_address
        self._remote = None
        if ray_address is not None:
            self._connect(ray_address)

    @property
    def description(self) -> str:
        if self._remote is not None:
            import ray

            return f"Ray cluster at {self.ray_address} ({int(ray.cluster_resources().get('CPU', 0))} CPUs)"
        devices = jax.local_devices()
        return f"{len(devices)} local {devices[0].platform.upper()} device{'s' if len(devices) > 1 else ''}"

    def _connect(self, address: str) -> None:
        from .._errors import HydrotactError

        try:
            import ray
        except ImportError:
            raise HydrotactError("--ray: Ray is not installed; pip install 'hydrotact[ray]' (or run without --ray: every local device is used)") from None
        if not ray.is_initialized():
            _check_reachable(address)
            try:
                ray.init(address=address, logging_level="ERROR", log_to_driver=False)
            except (ConnectionError, RuntimeError, ValueError):
                # (Ray's own message may name another address: the one it read from a stale session file)
                where = "no running Ray cluster was found on this machine" if address == "auto" else f"no Ray cluster answers at {address}"
                raise HydrotactError(f"--ray {address}: {where}; start one with 'ray start --head', or run without --ray") from None
        host = lambda tree: jax.tree_util.tree_map(lambda leaf: np.asarray(leaf) if eqx.is_array(leaf) else leaf, tree)
        self._model_ref, self._probe_ref = ray.put(host(self.model)), ray.put(host(self.probe))
        self._remote = ray.remote(num_cpus=1)(_ray_task)

    def compute(self, rows: np.ndarray, needs=None) -> dict:
        """Unit responses of the batch `rows` (n, 6) (a dict of NumPy arrays with
        UnitResponse's fields, leading axis n); `needs` as :func:`compute_block`."""
        rows = np.asarray(rows, dtype=np.float64)
        if self._remote is None:
            return compute_block(self.model, self.probe, rows, needs=needs)
        import ray

        x64 = bool(jax.config.read("jax_enable_x64"))
        slices = _slices(rows)
        starts = _slice_starts(self.probe, needs)
        starts = np.zeros(len(slices), dtype=np.int64) if starts is None else starts
        # At most RAY_SLICES per task, fewer when that leaves a CPU of the cluster idle.
        cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))
        per_task = max(1, min(RAY_SLICES, -(-len(slices) // cpus)))
        futures = [self._remote.remote(self._model_ref, self._probe_ref, slices[start : start + per_task], starts[start : start + per_task], x64) for start in range(0, len(slices), per_task)]
        pieces = ray.get(futures)
        return {name: np.concatenate([piece[name] for piece in pieces]).reshape(-1, *pieces[0][name].shape[2:])[: len(rows)] for name in _FIELDS}


RAY_CONNECT_TIMEOUT_S = 10.0


def _check_reachable(address: str) -> None:
    """Refuse at once an address (HOST:PORT or ray://HOST:PORT) where nothing listens:
    Ray's own init waits minutes for a cluster that is not there (measured: over 300 s
    for 127.0.0.1:6390, 2026-12-06)."""
    import re
    import socket

    from .._errors import HydrotactError

    found = re.fullmatch(r"(?:ray://)?\[?([^\]/]+?)\]?:(\d+)", address.strip())
    if found is None:
        return  # "auto", "local": Ray finds (or refuses) the cluster itself
    host, port = found.group(1), int(found.group(2))
    try:
        with socket.create_connection((host, port), timeout=RAY_CONNECT_TIMEOUT_S):
            pass
    except OSError as error:
        raise HydrotactError(
            f"--ray {address}: no Ray cluster answers at {host}:{port} ({error.strerror or error}, within {RAY_CONNECT_TIMEOUT_S:g} s); "
            "start one with 'ray start --head --port PORT', or run without --ray"
        ) from None
