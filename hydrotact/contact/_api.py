"""Entry points: the contact query (the probe computes its own surface; soft-soft
apart), batches over poses, and buffers grown on the host until nothing overflows."""

import equinox as eqx
import jax
import numpy as np

from .._buffers import run_growing
from .._errors import HydrotactError
from ..field import PressureField
from ._broadphase import Capacity, TetClusters, make_tet_clusters
from ._pose import Pose
from ._probes import AbstractProbe
from ._soft_soft import calc_soft_soft_surface
from ._surface import ContactSurface

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

    `other` is a probe (an :class:`AbstractProbe`: a :class:`RigidSurface` or a
    :class:`HalfSpace`), which computes the surface itself
    (:meth:`AbstractProbe.calc_contact_surface`), or another :class:`PressureField`
    (soft-soft). Check `.did_overflow` on the result, or use
    :func:`compute_contact_surface`, which does. `clusters` (from
    :func:`make_tet_clusters` on the soft mesh) makes the tet search hierarchical.
    """
    if isinstance(other, AbstractProbe):
        return other.calc_contact_surface(soft, X_SO, capacity, clusters)
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
    """Contact surfaces for one pose or a batch (X_SO with a leading axis), growing the
    overflowing buffers (:meth:`Capacity.grown_to`) and recomputing until no pose
    overflows (host; :func:`hydrotact._buffers.run_growing`). Never returns a
    truncated surface.

    **Returns:** (surface, the capacity that sufficed; reuse it for similar poses to
    avoid recompiling).
    """
    if clusters is None:
        clusters = make_tet_clusters(soft.vertices, soft.tets)
    run = _batched if np.ndim(X_SO.translation) == 2 else _single
    return run_growing(lambda size: run(soft, other, X_SO, size, clusters), capacity or Capacity())
