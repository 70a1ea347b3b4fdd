"""Host-level entry points: dispatch on the kind of the other body, batch over poses,
and grow the buffers until nothing overflows."""

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
    return jax.vmap(calc_contact_surface, in_axes=(None, None, 0, None, None))(soft, other, X_SO, capacity, clusters)


def compute_contact_surface(
    soft: PressureField, other, X_SO: Pose, capacity: Capacity | None = None, clusters: TetClusters | None = None
) -> tuple[ContactSurface, Capacity]:
    """Contact surfaces for one pose or a batch (X_SO with a leading axis), growing each
    overflowing buffer to the next power of two that fits, and recomputing, until no
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
        if not bool(np.any(np.asarray(surface.overflow))):
            return surface, capacity
        needed = np.max(np.asarray(surface.needed).reshape(-1, 3), axis=0)
        if needed[2] > MAX_PAIRS:
            raise HydrotactError(
                f"the contact needs more than {MAX_PAIRS} candidate pairs ({int(needed[2])} found); "
                "the bodies overlap too deeply"
            )
        grown = capacity.grown_to(needed)
        if grown == capacity:  # a count that does not map onto one buffer: grow them all
            grown = Capacity(2 * capacity.tets, 2 * capacity.others, 2 * capacity.pairs)
        capacity = grown
