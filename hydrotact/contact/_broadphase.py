"""Broad phase: which tets and triangles can touch, in fixed-capacity lists.

Candidates are found in two stages, each an axis-aligned-box test compacted with
`jnp.nonzero(..., size=capacity)`: first the tets (and rigid triangles, or the other
body's tets) that overlap the intersection of the two bodies' bounding boxes, then
the pairs among those whose own boxes overlap. Each list reports how many entries it
needed, so overflow is detected, never silently truncated.
"""

import equinox as eqx
import jax.numpy as jnp


class Capacity(eqx.Module):
    """Buffer sizes for the contact broad phase (static: changing one recompiles).

    - `tets`: soft tets near the other body.
    - `others`: rigid triangles (or the other soft body's tets) near the soft body.
    - `pairs`: candidate pairs, and so contact polygons.
    """

    tets: int = eqx.field(static=True, default=1024)
    others: int = eqx.field(static=True, default=1024)
    pairs: int = eqx.field(static=True, default=2048)

    def doubled(self) -> "Capacity":
        return Capacity(2 * self.tets, 2 * self.others, 2 * self.pairs)


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


def select_pairs(lo_a, hi_a, valid_a, lo_b, hi_b, valid_b, capacity: int):
    """Pairs (i, j) of overlapping boxes among two candidate lists.

    **Returns:** (i, j, pair_valid, num_pairs).
    """
    overlap = boxes_overlap(lo_a[:, None], hi_a[:, None], lo_b[None], hi_b[None])
    overlap = overlap & valid_a[:, None] & valid_b[None, :]
    flat, valid, count = select(overlap.reshape(-1), capacity)
    num_b = lo_b.shape[0]
    safe = jnp.where(valid, flat, 0)
    return safe // num_b, safe % num_b, valid, count
