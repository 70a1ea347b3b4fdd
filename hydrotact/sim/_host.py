"""The host entry to the forward model: chunks, buffer growth, progress, the cache of
unit responses, and resumable runs.

:func:`simulate` returns what :func:`hydrotact.sim.calc_simulation` returns, for
trajectories of any length: the unit responses of the trajectory's *distinct* poses
(a probe held still repeats its pose) are computed in jitted chunks of a few fixed
sizes, on a ladder of buffer sizes (:func:`calc_ladder_rung`: every buffer grown by the
rule of :mod:`hydrotact._buffers`, then scaled up together to the next rung) and
recomputed while any overflows, and then the pure
:func:`hydrotact.sim.calc_samples` applies the material and the barometer.

Unit responses are the expensive part, and the same ones serve a simulation and every
fit of its log: they are cached on disk (`hydrotact._files.cache_dir()`), keyed by the
content of the sensor model, the probe and the distinct poses. A long run also saves
its finished blocks to a checkpoint file (atomically, after each block), and a run
with the same inputs picks them up after an interruption (SIGKILL included).
"""

import dataclasses
import zipfile
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import __version__
from .._buffers import MAX_BUFFER, run_growing
from .._files import atomic_path, cache_dir, digest
from ..contact import CPU_POSE_GROUP, make_pose, map_over_poses
from ..visco import BarometerSignal, Prony
from ._model import SensorModel
from ._simulate import Samples, SimCapacity, UnitResponse, calc_samples, calc_unit_response
from ._trajectory import Trajectory, find_distinct_poses

# Distinct poses per saved block of a resumable run: one jitted chunk (a kill loses at
# most one block: seconds of work on a laptop CPU).
BLOCK = 128
_CACHE_VERSION = "unit-responses-2"


def calc_block_size(count: int) -> int:
    """Poses per block for `count` distinct poses: BLOCK, or for fewer poses the next
    power of two from CPU_POSE_GROUP (the block padded with its last pose). A shape
    compiles the contact and ray kernels anew (10-20 s on a laptop CPU), so blocks
    sized to each trajectory's pose count made a loop over presses compile once per
    press (host)."""
    return min(BLOCK, max(CPU_POSE_GROUP, 1 << (max(count, 1) - 1).bit_length()))


def calc_padded_length(count: int) -> int:
    """The sample count `simulate` runs the material and barometer pass at for
    `count` samples: 2**k times 1, 1.25, 1.5 or 1.75, at least 64 (at most a quarter
    more samples, four shapes per doubling; host). The pass is causal, so the padded
    tail changes no earlier sample."""
    if count <= 64:
        return 64
    octave = 1 << (count.bit_length() - 1)
    return next(octave * step // 4 for step in (4, 5, 6, 7, 8) if octave * step // 4 >= count)


def calc_ladder_rung(capacity: SimCapacity) -> SimCapacity:
    """The buffers a chunk is computed with: the lowest rung of the ladder
    SimCapacity() times 2**k (every buffer scaled alike, k of either sign) that holds
    `capacity` (host; no buffer past MAX_BUFFER). Growing each buffer on its own made
    a new combination of sizes, and so a compilation of the contact and ray kernels,
    for nearly every trajectory of a loop over presses (30 compilations of about 11 s,
    and counting, in the first 512 poses of benchmarks/generate.py's loop baseline, 11
    on the ladder); on the ladder
    a few rungs serve them all, as the dataset engine's ladder does."""
    base = SimCapacity().sizes
    k = max(int(np.ceil(np.log2(size / b))) for size, b in zip(capacity.sizes, base))
    rung = [b << k if k >= 0 else -(-b // (1 << -k)) for b in base]
    return SimCapacity(*(max(size, min(step, MAX_BUFFER)) for size, step in zip(capacity.sizes, rung)))


def calc_start_capacity() -> SimCapacity:
    """The buffers a simulation tries first: the ladder's second rung,
    SimCapacity() times 2 (host). A press of the built-in probes overflows the bottom
    rung (the Ø2 mm cylinder 0.45 mm into pad5x5 needs 1408 polygons against its
    1024), so starting there compiled the chunk kernel twice, 5-10 s each on a 2-core
    CPU, for every first simulation of a sensor and probe; a chunk that needs the
    bottom rung runs on the second instead (the readings agree to rounding), a chunk
    that needs more climbs from there as before."""
    return SimCapacity(*(2 * size for size in SimCapacity().sizes))


@eqx.filter_jit
def _chunk_response(model, probe, X_SR, capacity):
    return map_over_poses(lambda X: calc_unit_response(model, probe, X, capacity), X_SR)


def compute_unit_responses(model: SensorModel, probe, X_SR, capacity: SimCapacity | None = None, chunk: int = 128, on_chunk=None):
    """Unit responses for a batch of poses, in jitted chunks of `chunk` poses, growing
    buffers (and recomputing the chunk) whenever one overflows (host; `on_chunk(n)`
    is called after each chunk of n poses, for progress).

    **Returns:** (UnitResponse with a leading sample axis, as NumPy arrays; the
    capacity that sufficed).
    """
    capacity = capacity or calc_start_capacity()
    count = X_SR.translation.shape[0]
    chunk = max(1, min(chunk, count))
    pieces = []
    for start in range(0, count, chunk):
        index = np.minimum(np.arange(start, start + chunk), count - 1)  # pad the last chunk
        poses = jax.tree_util.tree_map(lambda a, index=index: a[index], X_SR)
        unit, capacity = run_growing(lambda size, poses=poses: _chunk_response(model, probe, poses, calc_ladder_rung(size)), capacity)
        used = min(chunk, count - start)
        pieces.append(jax.tree_util.tree_map(lambda a, used=used: np.asarray(a)[:used], unit))
        if on_chunk is not None:
            on_chunk(used)
    unit = jax.tree_util.tree_map(lambda *parts: np.concatenate(parts), *pieces)
    return unit, capacity


def _content_digest(*trees) -> str:
    """A digest of pytrees' array contents, structure and static fields (host)."""
    parts = []
    for tree in trees:
        leaves, treedef = jax.tree_util.tree_flatten(tree)
        parts.append(str(treedef))
        parts += [np.ascontiguousarray(np.asarray(leaf)).tobytes() for leaf in leaves]
    return digest(*parts)


def calc_responses_key(model: SensorModel, probe, pose_rows) -> str:
    """The key of the unit responses of `model` and `probe` at `pose_rows` (D, 6):
    a digest of their contents, so any change to the mesh, field, layout, ray count,
    probe or poses makes a new key (host)."""
    rows = np.ascontiguousarray(np.asarray(pose_rows, dtype=np.float64))
    return digest(_CACHE_VERSION, __version__, _content_digest(model, probe), rows.tobytes())


def _cache_path(key: str) -> Path:
    return cache_dir() / "unit_responses" / f"{key}.npz"


def _load_blocks(path: Path, key: str) -> list[dict]:
    """The blocks saved in `path` if it was written for `key`; [] if it is absent,
    of other inputs, or unreadable (it is only a cache: recompute rather than fail)."""
    if not path.is_file():
        return []
    try:
        with path.open("rb") as handle, np.load(handle, allow_pickle=False) as saved:  # our handle: np.load leaks its own on a bad zip
            if str(saved["key"]) != key:
                return []
            return [dict((name[len(f"{k}/"):], saved[name]) for name in saved.files if name.startswith(f"{k}/")) for k in range(int(saved["num_blocks"]))]
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return []


def _save_blocks(path: Path, key: str, blocks: list[dict]) -> None:
    arrays = {f"{k}/{name}": value for k, block in enumerate(blocks) for name, value in block.items()}
    with atomic_path(path, suffix=".npz") as tmp:
        np.savez(tmp, key=np.array(key), num_blocks=np.array(len(blocks)), **arrays)


def compute_pose_responses(model: SensorModel, probe, pose_rows, *, progress: bool = False, checkpoint=None, cache: bool = True, capacity: SimCapacity | None = None) -> UnitResponse:
    """Unit responses at distinct poses, block by block (host).

    **Arguments:**

    - `pose_rows`: (D, 6) translation (m) and rotation vector (rad) per pose.
    - `progress`: show a progress bar over the poses.
    - `checkpoint`: a file to save finished blocks in (atomically, after each); a
      checkpoint of the same inputs left by an interrupted run is resumed from. The
      caller removes it once its own output is written. Without one, a cached run
      keeps its blocks beside its cache entry (`KEY.partial.npz`, removed once the
      entry is written): a killed fit of many logs resumes inside the log it was on.
    - `cache`: look the responses up in, and store them into, the on-disk cache.

    **Returns:** UnitResponse (NumPy arrays, leading axis D).
    """
    from tqdm.auto import tqdm

    rows = np.asarray(pose_rows, dtype=np.float64)
    key = calc_responses_key(model, probe, rows)
    if cache:
        saved = _load_blocks(_cache_path(key), key)
        if saved:
            return UnitResponse(**saved[0])
    own_checkpoint = checkpoint is None and cache
    checkpoint = _cache_path(key).with_suffix(".partial.npz") if own_checkpoint else (None if checkpoint is None else Path(checkpoint))
    blocks = [] if checkpoint is None else _load_blocks(checkpoint, key)
    done = sum(len(block["area"]) for block in blocks)  # not len(blocks) * BLOCK: they may have been saved with another BLOCK
    count = len(rows)
    with tqdm(total=count, initial=min(count, done), unit="pose", desc=f"simulating {count} distinct poses", disable=not progress) as bar:
        if done < count:  # the first chunk compiles the contact and ray kernels: say so, not a frozen 0 %
            bar.set_postfix_str("compiling the contact kernels (once per sensor and probe)", refresh=True)

        def advance(used):
            bar.set_postfix_str("", refresh=False)
            bar.update(min(used, count - bar.n))  # the last block's padding is no pose

        size = calc_block_size(count)  # every block one shape (the last padded): one compilation
        for start in range(done, count, BLOCK):
            stop = min(count, start + BLOCK)
            index = np.minimum(np.arange(start, start + size), count - 1)
            X_SR = jax.vmap(make_pose)(jnp.asarray(rows[index, :3]), jnp.asarray(rows[index, 3:]))
            unit, capacity = compute_unit_responses(model, probe, X_SR, capacity, chunk=size, on_chunk=advance)
            blocks.append({field.name: np.asarray(getattr(unit, field.name))[: stop - start] for field in dataclasses.fields(unit)})
            if checkpoint is not None:
                _save_blocks(checkpoint, key, blocks)
    arrays = {name: np.concatenate([block[name] for block in blocks]) for name in blocks[0]}
    if cache:
        _save_blocks(_cache_path(key), key, [arrays])
    if own_checkpoint:
        checkpoint.unlink(missing_ok=True)
    return UnitResponse(**arrays)


def compute_trajectory_responses(model: SensorModel, probe, trajectory: Trajectory, **options) -> UnitResponse:
    """Unit responses along a trajectory, each distinct pose computed (or looked up)
    once (host; `options` as :func:`compute_pose_responses`).

    **Returns:** UnitResponse (NumPy arrays, leading axis: the trajectory's samples).
    """
    rows, index = find_distinct_poses(trajectory)
    unit = compute_pose_responses(model, probe, rows, **options)
    return jax.tree_util.tree_map(lambda a: a[index], unit)


_calc_samples = eqx.filter_jit(calc_samples)


def simulate(
    model: SensorModel,
    material: Prony,
    probe,
    trajectory: Trajectory,
    *,
    barometer: BarometerSignal | None = None,
    key=None,
    capacity: SimCapacity | None = None,
    progress: bool = False,
    checkpoint=None,
    cache: bool = True,
) -> Samples:
    """Simulate the sensor along a probe trajectory of any length (host entry point).

    The same Samples as :func:`hydrotact.sim.calc_simulation` with the same
    arguments, computed in chunks over the trajectory's distinct poses with buffers
    grown until nothing overflows (never truncated), an optional progress bar, the
    unit-response cache and an optional checkpoint (see
    :func:`compute_pose_responses`).

    **Returns:** Samples (NumPy arrays).
    """
    unit = compute_trajectory_responses(model, probe, trajectory, progress=progress, checkpoint=checkpoint, cache=cache, capacity=capacity)
    times = np.asarray(trajectory.times)
    count = len(times)
    # One compilation per padded length, not per trajectory length (a loop over presses
    # of many lengths compiled one program each, until XLA ran out of memory). The pass
    # is causal and the barometer noise of the first `count` rows of a longer draw is
    # the draw of `count` rows (partitionable threefry, JAX's default), so the samples
    # are those of the unpadded trajectory.
    extra = calc_padded_length(count) - count if key is None or jax.config.jax_threefry_partitionable else 0
    if extra:
        step = times[-1] - times[-2] if count > 1 else 1.0
        times = np.concatenate([times, times[-1] + step * np.arange(1, extra + 1, dtype=times.dtype)])
        unit = jax.tree_util.tree_map(lambda a: np.concatenate([a, np.repeat(a[-1:], extra, axis=0)]), unit)
    unit = jax.tree_util.tree_map(jnp.asarray, unit)
    samples = _calc_samples(model, material, jnp.asarray(times), unit, barometer, key)
    modulus = samples.modulus  # the only field without a sample axis
    samples = jax.tree_util.tree_map(lambda a: np.asarray(a)[:count], dataclasses.replace(samples, modulus=None))
    return dataclasses.replace(samples, modulus=np.asarray(modulus))
