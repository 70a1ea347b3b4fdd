"""Broad phase: which tets and triangles can touch, in fixed-capacity lists.

Candidates are found in two stages, each an axis-aligned-box test compacted with
`jnp.nonzero(..., size=capacity)`: first the tets (and rigid triangles, or the other
body's tets) that overlap the intersection of the two bodies' bounding boxes, then
the pairs among those whose own boxes overlap. Each list reports how many entries it
needed, so overflow is detected, never silently truncated.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._types import Array, Int


class Capacity(eqx.Module):
    """Buffer sizes for the contact broad phase (static: changing one recompiles).

    - `tets`: soft tets near the other body.
    - `others`: rigid triangles (or the other soft body's tets) near the soft body.
    - `pairs`: candidate pairs, and so contact polygons.
    """

    tets: int = eqx.field(static=True, default=256)
    others: int = eqx.field(static=True, default=256)
    pairs: int = eqx.field(static=True, default=1024)

    def grown_to(self, needed) -> "Capacity":
        """The smallest capacity, in powers of two, at least this one and `needed`."""

        def fit(current, need):
            size = current
            while size < need:
                size *= 2
            return size

        return Capacity(fit(self.tets, needed[0]), fit(self.others, needed[1]), fit(self.pairs, needed[2]))


def calc_boxes(points):
    """Axis-aligned boxes (lo, hi) of point groups (..., k, 3)."""
    return jnp.min(points, axis=-2), jnp.max(points, axis=-2)


def boxes_overlap(lo_a, hi_a, lo_b, hi_b):
    return jnp.all((lo_a <= hi_b) & (lo_b <= hi_a), axis=-1)


def select(mask, capacity: int):
    """Indices of True entries, padded with -1 to `capacity`, a validity mask, and the
    number of True entries (which may exceed capacity: overflow)."""
    (index,) = jnp.nonzero(mask, size=capacity, fill_value=-1)
    return index, index >= 0, jnp.sum(mask)


def select_pairs(lo_a, hi_a, valid_a, lo_b, hi_b, valid_b, capacity: int, also=None):
    """Pairs (i, j) of overlapping boxes among two candidate lists, optionally also
    passing the (len_a, len_b) mask `also` (a finer separation test).

    **Returns:** (i, j, pair_valid, num_pairs).
    """
    overlap = boxes_overlap(lo_a[:, None], hi_a[:, None], lo_b[None], hi_b[None])
    overlap = overlap & valid_a[:, None] & valid_b[None, :]
    if also is not None:
        overlap = overlap & also
    flat, valid, count = select(overlap.reshape(-1), capacity)
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


def box_meets_region(region_lo, region_hi):
    """A box test for :func:`select_clustered_tets`: overlap with an axis-aligned region."""
    return lambda lo, hi: boxes_overlap(lo, hi, _like(region_lo, lo), _like(region_hi, lo))


def box_meets_plane(point, normal):
    """A box test for :func:`select_clustered_tets`: the plane passes through the box."""

    def meets(lo, hi):
        centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        distance = jnp.sum((centre - _like(point, centre)) * _like(normal, centre), axis=-1)
        reach = jnp.sum(half * _like(jnp.abs(normal), half), axis=-1)
        return jnp.abs(distance) <= reach

    return meets


def select_clustered_tets(clusters: TetClusters, tet_lo, tet_hi, meets, capacity: int):
    """Tets whose boxes pass the test `meets(lo, hi)`, found through the clusters.

    **Returns:** (tet indices (capacity,) with -1 for none, validity mask, slots
    needed): capacity is rounded down to whole clusters; `needed` counts the slots of
    every cluster that overlaps the region.
    """
    members = jnp.asarray(clusters.members)
    safe = jnp.maximum(members, 0)
    real = members >= 0
    big = jnp.asarray(jnp.inf, tet_lo.dtype)
    cluster_lo = jnp.min(jnp.where(real[..., None], tet_lo[safe], big), axis=1)
    cluster_hi = jnp.max(jnp.where(real[..., None], tet_hi[safe], -big), axis=1)
    num_slots = max(1, capacity // clusters.cluster_size)
    hit, hit_valid, num_hit = select(meets(cluster_lo, cluster_hi), num_slots)
    candidates = members[jnp.maximum(hit, 0)]  # (num_slots, cluster_size)
    valid = hit_valid[:, None] & (candidates >= 0)
    candidates = jnp.maximum(candidates, 0)
    valid = valid & meets(tet_lo[candidates], tet_hi[candidates])
    return jnp.where(valid, candidates, -1).reshape(-1), valid.reshape(-1), num_hit * clusters.cluster_size
