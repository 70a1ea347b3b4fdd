"""Host-level entry points: dispatch on the kind of the other body, batch over poses,
and grow the buffers until nothing overflows."""

import dataclasses

import equinox as eqx
import jax
import numpy as np

from .._errors import HydrotactError
from ..field import PressureField
from ._broadphase import Capacity, TetClusters, make_tet_clusters
from ._half_space import calc_half_space_surface
from ._pose import Pose
from ._rigid import HalfSpace, RigidSurface
from ._soft_rigid import calc_soft_rigid_surface
from ._soft_soft import calc_soft_soft_surface
from ._surface import ContactSurface

MAX_PAIRS = 1 << 22

# Poses computed together (vmapped) on a CPU; a batch runs as a loop over such groups.
# The kernels' working arrays are (poses, 3, polygons): at 16 poses they stay in the
# CPU's caches, and pad5x5 + 2 mm cylinder runs about 1.15x faster than at 64
# (benchmarks/contact.py --chunk). Other backends vmap the whole batch at once.
CPU_POSE_GROUP = 16


def map_over_poses(fn, X_SO: Pose):
    """`fn(X)` for each pose of a batch X_SO (leading axis), stacked: vmapped in
    groups of CPU_POSE_GROUP on a CPU (`lax.map` over the groups), all at once on an
    accelerator. Differentiable like vmap."""
    if jax.default_backend() == "cpu":
        return jax.lax.map(fn, X_SO, batch_size=CPU_POSE_GROUP)
    return jax.vmap(fn)(X_SO)


def calc_contact_surface(
    soft: PressureField, other, X_SO: Pose, capacity: Capacity = Capacity(), clusters: TetClusters | None = None
) -> ContactSurface:
    """The contact surface between `soft` (frame S) and `other` at pose X_SO (pure).

    `other` is a :class:`RigidSurface`, a :class:`HalfSpace` or another
    :class:`PressureField` (soft-soft). Check `.overflow` on the result, or use
    :func:`compute_contact_surface`, which does. `clusters` (from
    :func:`make_tet_clusters` on the soft mesh) makes the tet search hierarchical.
    """
    if isinstance(other, HalfSpace):
        return calc_half_space_surface(soft, X_SO, capacity, clusters=clusters)
    if isinstance(other, RigidSurface):
        return calc_soft_rigid_surface(soft, other, X_SO, capacity, clusters=clusters)
    if isinstance(other, PressureField):
        return calc_soft_soft_surface(soft, other, X_SO, capacity)
    raise HydrotactError(f"cannot compute contact with a {type(other).__name__}")


@eqx.filter_jit
def _single(soft, other, X_SO, capacity, clusters):
    return calc_contact_surface(soft, other, X_SO, capacity, clusters)


@eqx.filter_jit
def _batched(soft, other, X_SO, capacity, clusters):
    return map_over_poses(lambda X: calc_contact_surface(soft, other, X, capacity, clusters), X_SO)


def compute_contact_surface(
    soft: PressureField, other, X_SO: Pose, capacity: Capacity | None = None, clusters: TetClusters | None = None
) -> tuple[ContactSurface, Capacity]:
    """Contact surfaces for one pose or a batch (X_SO with a leading axis), growing each
    overflowing buffer to the next size that fits (Capacity.grown_to), and recomputing, until no
    pose overflows. Never returns a truncated surface.

    **Returns:** (surface, the capacity that sufficed; reuse it for similar poses to
    avoid recompiling).
    """
    capacity = capacity or Capacity()
    if clusters is None:
        clusters = make_tet_clusters(soft.vertices, soft.tets)
    batched = np.ndim(X_SO.translation) == 2
    while True:
        surface = (_batched if batched else _single)(soft, other, X_SO, capacity, clusters)
        overflow = np.asarray(surface.overflow)
        if not bool(np.any(overflow)):
            return surface, capacity
        capacity = grown_contact_capacity(capacity, np.asarray(surface.needed)[overflow] if batched else surface.needed)


def grown_contact_capacity(capacity: Capacity, needed) -> Capacity:
    """The capacity to retry with after an overflow: each buffer grown to the next
    size (Capacity.grown_to) that holds what the overflowing surfaces `needed` (rows of
    `ContactSurface.needed`), or every buffer doubled where the counts map onto none;
    a clear error past MAX_PAIRS candidate pairs (host)."""
    needed = np.asarray(needed)
    needed = np.max(needed.reshape(-1, needed.shape[-1]), axis=0)
    most = int(max(needed[2:]))  # candidate pairs and polygons
    if most > MAX_PAIRS:
        raise HydrotactError(
            f"the contact needs more than {MAX_PAIRS} candidate pairs ({most} found); "
            "the bodies overlap too deeply"
        )
    grown = capacity.grown_to(needed)
    if grown == capacity:  # a count that does not map onto one buffer: grow them all
        grown = Capacity(*(2 * getattr(capacity, field.name) for field in dataclasses.fields(capacity)))
    return grown
