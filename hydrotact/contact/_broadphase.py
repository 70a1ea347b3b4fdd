"""Broad phase: which tets and triangles can touch, in fixed-capacity lists.

Candidates are found in stages, each a test compacted into a fixed-capacity list by
:func:`hydrotact._buffers.compact_indices`: first the tets (through their
clusters) and the rigid triangles, or the other body's tets, that overlap the
intersection of the two bodies' bounding boxes, then the pairs among those (the
kernels add their own finer tests). Each list reports how many entries it needed,
so overflow is detected, never silently truncated.
"""

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._buffers import AbstractCapacity, compact_indices
from .._types import Array, Int


class Capacity(AbstractCapacity):
    """Buffer sizes for the contact broad phase (static: changing one recompiles), in
    the order of :attr:`ContactSurface.needed`.

    - `tets`: soft tets near the other body (in whole clusters when clustered).
    - `others`: rigid triangles (or the other soft body's tets) near the soft body.
    - `pairs`: soft-rigid candidate pairs, (tet, triangle) whose boxes overlap,
      which the finer plane tests then sort (not used by the half-space and
      soft-soft kernels: their `needed[2]` reads 0).
    - `polygons`: the contact polygons, the size of the returned surface: the
      candidate pairs that survive the separating-plane tests (soft-rigid), the cut
      tets (half-space), the overlapping tet pairs (soft-soft).

    Grown by the one rule of :meth:`AbstractCapacity.grown_to`.
    """

    purpose: ClassVar[str] = "the contact"
    advice: ClassVar[str] = "the bodies overlap too deeply"

    tets: int = eqx.field(static=True, default=256)
    others: int = eqx.field(static=True, default=256)
    pairs: int = eqx.field(static=True, default=4096)
    polygons: int = eqx.field(static=True, default=1024)


def calc_boxes(points):
    """Axis-aligned boxes (lo, hi) of point groups (..., k, 3)."""
    return jnp.min(points, axis=-2), jnp.max(points, axis=-2)


def boxes_overlap(lo_a, hi_a, lo_b, hi_b):
    return jnp.all((lo_a <= hi_b) & (lo_b <= hi_a), axis=-1)


def select_pairs(lo_a, hi_a, valid_a, lo_b, hi_b, valid_b, capacity: int, also=None):
    """Pairs (i, j) of overlapping boxes among two candidate lists, optionally also
    passing the (len_a, len_b) mask `also` (a finer separation test).

    **Returns:** (i, j, pair_valid, num_pairs).
    """
    overlap = boxes_overlap(lo_a[:, None], hi_a[:, None], lo_b[None], hi_b[None])
    overlap = overlap & valid_a[:, None] & valid_b[None, :]
    if also is not None:
        overlap = overlap & also
    flat, valid, count = compact_indices(overlap.reshape(-1), capacity)
    num_b = lo_b.shape[0]
    safe = jnp.where(valid, flat, 0)
    return safe // num_b, safe % num_b, valid, count


class TetClusters(eqx.Module):
    """Tets grouped into spatially compact clusters (a two-level bounding-volume
    hierarchy), built once on the host: `members` (num_clusters, cluster_size) holds
    tet indices in Morton order of their centroids, padded with -1.

    A query tests the few-hundred cluster boxes first, then only the tets of the
    clusters that pass, instead of every tet of the mesh.
    """

    members: Int[Array, "num_clusters cluster_size"]

    @property
    def cluster_size(self) -> int:
        return self.members.shape[1]


def make_tet_clusters(vertices, tets, cluster_size: int = 32) -> TetClusters:
    """Cluster tets by the Morton (Z-order) code of their centroids (host)."""
    vertices, tets = np.asarray(vertices), np.asarray(tets)
    centroids = vertices[tets].mean(axis=1)
    lo, hi = centroids.min(axis=0), centroids.max(axis=0)
    grid = np.clip(((centroids - lo) / np.maximum(hi - lo, 1e-300) * 1023).astype(np.int64), 0, 1023)
    code = np.zeros(len(tets), dtype=np.int64)
    for bit in range(10):
        for axis in range(3):
            code |= ((grid[:, axis] >> bit) & 1) << (3 * bit + axis)
    order = np.argsort(code, kind="stable")
    padded = np.full(-(-len(order) // cluster_size) * cluster_size, -1, dtype=np.int64)
    padded[: len(order)] = order
    return TetClusters(members=padded.reshape(-1, cluster_size).astype(np.int32))


def _like(vector, boxes):
    """`vector` (3,) shaped to broadcast against `boxes` (..., 3) explicitly."""
    return jnp.reshape(vector, (1,) * (boxes.ndim - 1) + (3,))


# A box passes the plane test when the plane comes within this fraction of the
# coordinates' magnitude of it (a picometre at centimetre scale). The box's reach
# along the normal and the vertex heights the kernel cuts by are sums of different
# products, each rounded: a box whose face lies exactly on the plane (a vertex layer
# of a structured mesh) must never be rejected by that last bit, since its tets are
# the ones whose faces the plane cuts. Letting in a box that is a picometre away
# costs only its tets' (empty) sections.
PLANE_TOLERANCE = 1e-10


def box_meets_plane(point, normal):
    """A box test for :func:`select_clusters`: the plane (point, unit normal) passes
    through the box or touches it, within PLANE_TOLERANCE of the coordinates'
    magnitude (never rejects a box the plane touches)."""

    def meets(lo, hi):
        centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        distance = jnp.sum((centre - _like(point, centre)) * _like(normal, centre), axis=-1)
        reach = jnp.sum(half * _like(jnp.abs(normal), half), axis=-1)
        magnitude = jnp.maximum(jnp.max(jnp.maximum(jnp.abs(lo), jnp.abs(hi)), axis=-1), jnp.max(jnp.abs(point)))
        return jnp.abs(distance) <= reach + PLANE_TOLERANCE * magnitude

    return meets


def calc_cluster_boxes(clusters: TetClusters, tet_points):
    """Axis-aligned boxes (lo, hi) of each cluster's tets (num_clusters, 3)."""
    members = jnp.asarray(clusters.members)
    points = tet_points[jnp.maximum(members, 0)]  # (num_clusters, cluster_size, 4, 3)
    real = (members >= 0)[..., None, None]
    big = jnp.asarray(jnp.inf, tet_points.dtype)
    return jnp.min(jnp.where(real, points, big), axis=(1, 2)), jnp.max(jnp.where(real, points, -big), axis=(1, 2))


def select_clusters(clusters: TetClusters, tet_points, meets, capacity: int):
    """The clusters whose boxes pass `meets(lo, hi)`, as their member tets.

    **Returns:** (member tets (num_slots, cluster_size) with -1 for none, validity,
    slots needed), num_slots = capacity // cluster_size (at least 1); `needed`
    counts the slots of every passing cluster.
    """
    members = jnp.asarray(clusters.members)
    cluster_lo, cluster_hi = calc_cluster_boxes(clusters, tet_points)
    hit, hit_valid, num_hit = compact_indices(meets(cluster_lo, cluster_hi), max(1, capacity // clusters.cluster_size))
    candidates = members[jnp.maximum(hit, 0)]
    valid = hit_valid[:, None] & (candidates >= 0)
    return jnp.where(valid, candidates, -1), valid, num_hit * clusters.cluster_size
