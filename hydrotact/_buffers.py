"""Fixed-capacity buffers: their sizes, compaction into them, and growing them.

Kernels whose results vary in size (contact polygons, candidate pairs) write them
into buffers of a fixed, static capacity, as jax-md's neighbour lists do: a jitted
kernel compacts its candidates into each buffer with :func:`compact_indices`, and
reports on its result `did_overflow` (some buffer was too small: the result is
incomplete) and `needed` (how many entries each buffer would have needed, in the
order of its capacity's `sizes`). The host then grows the capacity
(:meth:`AbstractCapacity.grown_to`) and recomputes, which :func:`run_growing` does
until nothing overflows. A result is never silently truncated.

One growth rule serves every kernel: each buffer grows to the smallest size of the
form m 2^k with 8 <= m <= 15 that holds what it needed (at most 12.5 % more than
needed, and few distinct sizes to compile), never below its current size; counts
that fit every buffer although the result overflowed (a buffer whose count the
kernel cannot report exactly) grow every buffer by 2x; past :data:`MAX_BUFFER`
entries in one buffer the host raises a :class:`HydrotactError`. Buffers also
shrink: after a result that fits, a buffer more than :data:`SHRINK_BELOW` times
larger than the same rounding of what it needed is cut to that size
(:meth:`AbstractCapacity.fitted_to`), so one large input does not slow every later
one, and the sizes stay few.
"""

import dataclasses
from collections.abc import Callable
from typing import Any, ClassVar, Self, TypeVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._errors import HydrotactError

MAX_BUFFER = 1 << 22
"""The most entries any one buffer may grow to (4,194,304)."""

SHRINK_BELOW = 4
"""A buffer shrinks after a result that fits when it is more than this many times the
size that would hold what it needed (a margin against growing back at once)."""

# Masks at least this long are compacted by a binary search over their running count,
# shorter ones by a blocked prefix sum and one scatter (see compact_indices), unless
# they are at least WORDS_FROM times the buffer's size: then by 32-bit words.
SEARCH_FROM = 1 << 17
WORDS_FROM = 8

_Capacity = TypeVar("_Capacity", bound="AbstractCapacity")


def _fit(current: int, need: int) -> int:
    """The smallest m 2^k (8 <= m <= 15) that holds `need`, but at least `current`."""
    if need <= current:
        return current
    scale = 1
    while 15 * scale < need:
        scale *= 2
    return max(current, next(m * scale for m in range(8, 16) if m * scale >= need))


class AbstractCapacity(eqx.Module):
    """Buffer sizes of one kernel (abstract): static int fields, one per buffer, in
    the order of the kernel's `needed` (changing one recompiles the kernel).

    Subclasses declare their buffers as `eqx.field(static=True, default=...)` int
    fields and set the class variables `purpose` (what fills the buffers, for the
    error past :data:`MAX_BUFFER`, e.g. "the contact") and optionally `advice` (what
    such an overflow usually means).
    """

    purpose: ClassVar[str] = "a kernel"
    advice: ClassVar[str] = ""

    @property
    def sizes(self) -> tuple[int, ...]:
        """Each buffer's size, in field order."""
        return tuple(getattr(self, field.name) for field in dataclasses.fields(self))

    def rounded_up(self) -> Self:
        """Every buffer rounded up to a power of two (host): few distinct capacities,
        so few compilations of the kernels they size."""
        return type(self)(*(1 << (int(size) - 1).bit_length() for size in self.sizes))

    def grown_to(self, needed) -> Self:
        """The capacity to retry with after an overflow (host).

        Each buffer is rounded up to the smallest m 2^k (8 <= m <= 15) that holds its
        entry of `needed`, never below its current size; where that changes nothing
        (the counts fit, yet the result overflowed) every buffer doubles.

        **Arguments:**

        - `needed`: entries each buffer needed, shaped like `sizes`; rows of several
          results (a leading batch axis) take their maximum.

        **Returns:** a capacity of the same type.

        **Raises:** :class:`HydrotactError` when a buffer would need more than
        :data:`MAX_BUFFER` entries.
        """
        names = [field.name for field in dataclasses.fields(self)]
        needed = np.asarray(needed, dtype=np.int64).reshape(-1, len(names))
        needed = np.max(needed, axis=0) if needed.shape[0] else np.zeros(len(names), np.int64)
        for name, need in zip(names, needed.tolist()):
            if need > MAX_BUFFER:
                raise HydrotactError(
                    f"{self.purpose} needs more than {MAX_BUFFER} entries in its {name} buffer "
                    f"({need} found){'; ' + self.advice if self.advice else ''}"
                )
        grown = type(self)(**{name: _fit(size, need) for name, size, need in zip(names, self.sizes, needed.tolist())})
        if grown == self:  # counts that do not map onto one buffer: grow them all
            if any(2 * size > MAX_BUFFER for size in self.sizes):
                raise HydrotactError(
                    f"{self.purpose} overflows its buffers {dict(zip(names, self.sizes))} although "
                    f"the counts fit them, and doubling them passes {MAX_BUFFER} entries"
                )
            grown = type(self)(**{name: 2 * size for name, size in zip(names, self.sizes)})
        return grown

    def fitted_to(self, needed) -> Self:
        """The capacity to keep after a result that did not overflow (host).

        A buffer more than :data:`SHRINK_BELOW` times the smallest m 2^k (8 <= m <=
        15) that holds its entry of `needed` shrinks to that size; the others keep
        theirs.

        **Arguments:**

        - `needed`: entries each buffer needed, shaped like `sizes`; rows of several
          results (a leading batch axis) take their maximum.

        **Returns:** a capacity of the same type (this one when nothing shrinks).
        """
        names = [field.name for field in dataclasses.fields(self)]
        needed = np.asarray(needed, dtype=np.int64).reshape(-1, len(names))
        if not needed.shape[0]:
            return self
        # At least the smallest size (8): a batch with nothing in a buffer (no contact)
        # must not leave it empty for the next batch, which would index into it.
        fitted = [_fit(0, max(need, 1)) for need in np.max(needed, axis=0).tolist()]
        sizes = [fit if size > SHRINK_BELOW * fit else size for size, fit in zip(self.sizes, fitted)]
        return self if tuple(sizes) == self.sizes else type(self)(**dict(zip(names, sizes)))


def run_growing(compute: Callable[[_Capacity], Any], capacity: _Capacity) -> tuple[Any, _Capacity]:
    """Call `compute(capacity)`, growing the capacity and recomputing until its
    result does not overflow (host); the capacity returned is fitted to that result.

    The result must have `did_overflow` (a bool, or bools with leading batch axes)
    and `needed` (shaped like `capacity.sizes`, after the same batch axes). After an
    overflow the capacity grows (:meth:`AbstractCapacity.grown_to`) to the largest
    count each buffer needed among the rows that overflowed. The result that fits is
    returned with the capacity cut to its needs where it is far larger
    (:meth:`AbstractCapacity.fitted_to`): a batch after a large one then runs with
    buffers sized for itself, not for the largest input ever met.

    **Arguments:**

    - `compute`: capacity -> result; usually a jitted kernel (each new capacity
      compiles it once more).
    - `capacity`: the sizes to try first.

    **Returns:** (the result that fitted, the capacity fitted to it; reuse it for
    similar inputs to avoid recompiling).
    """
    while True:
        result = compute(capacity)
        did_overflow = np.asarray(result.did_overflow)
        if not did_overflow.any():
            return result, capacity.fitted_to(result.needed)
        needed = np.asarray(result.needed)
        capacity = capacity.grown_to(needed[did_overflow] if did_overflow.ndim else needed)


def _blocked_cumsum(flags, block: int = 128):
    """Inclusive prefix sum of a 1-D int array, blocked (a scan within blocks of
    `block`, then one over the block totals): several times faster on the CPU than a
    scan over the whole array."""
    n = flags.shape[0]
    if n <= block:
        return jnp.cumsum(flags)
    padded = -(-n // block) * block
    blocks = jnp.concatenate([flags, jnp.zeros(padded - n, flags.dtype)]).reshape(-1, block)
    within = jnp.cumsum(blocks, axis=1)
    totals = within[:, -1]
    return (within + (jnp.cumsum(totals) - totals)[:, None]).reshape(-1)[:n]


def _compact_words(flags, size: int):
    """compact_indices of a 1-D bool mask through 32-bit words: the mask packed 32
    entries a word, the words' set bits counted (`population_count`) and summed, then
    for each output slot a binary search over the W = n/32 words' running count and one
    over the bits of its word (5 halvings by masked counts). O(n + size log W); the
    running count and the searches run over n/32 entries, not n."""
    n = flags.shape[0]
    num_words = -(-n // 32)
    packed = jnp.concatenate([flags, jnp.zeros(num_words * 32 - n, flags.dtype)]).reshape(num_words, 32)
    weights = jnp.uint32(1) << jnp.arange(32, dtype=jnp.uint32)
    words = jnp.sum(jnp.where(packed, weights, jnp.uint32(0)), axis=1, dtype=jnp.uint32)
    counts = jax.lax.population_count(words).astype(jnp.int32)
    ends = jnp.cumsum(counts)
    slots = jnp.arange(size, dtype=jnp.int32)
    word = jnp.minimum(jnp.searchsorted(ends, slots, side="right", method="scan_unrolled"), num_words - 1).astype(jnp.int32)
    rank = slots - (ends[word] - counts[word])  # the slot's entry is the rank-th set bit of its word (from 0)
    bits = words[word]
    position = jnp.zeros(size, jnp.uint32)
    for step in (16, 8, 4, 2, 1):  # the largest position with at most `rank` set bits below it
        trial = position + jnp.uint32(step)
        below = bits & ((jnp.uint32(1) << trial) - jnp.uint32(1))
        position = jnp.where(jax.lax.population_count(below).astype(jnp.int32) <= rank, trial, position)
    filled = slots < ends[-1]
    return jnp.where(filled, word * 32 + position.astype(jnp.int32), -1), filled, ends[-1]


def compact_indices(mask, size: int):
    """Indices of the True entries of a mask, in order, padded with -1 to `size`:
    `jnp.nonzero(mask.ravel(), size=size, fill_value=-1)`, with the overflow counted.

    Three exact methods, chosen by the mask's length and `size` (static). A mask at
    least WORDS_FROM times `size` is packed into 32-bit words (:func:`_compact_words`):
    measured on the CPU, vmapped over 16 masks, 1.6-4.7x faster than the two methods
    below for masks of 5e3 to 1e6 entries (450k entries into 2,304 slots, the dense box
    test of the generator's sphere on sphere8: 1.94 -> 0.55 ms), and 3.7x slower for
    5e3 entries into 4,096 slots (the search then costs more than the pass). Otherwise,
    by the mask's length: below `SEARCH_FROM`
    entries, a blocked prefix sum gives each True entry its slot and one scatter
    writes the indices (entries past `size` are dropped, and counted); from it on, a
    running count and a binary search for each output slot (O(n + size log n), no
    scatter), which measured 10-30 % faster on the CPU for the taxel and large
    contact masks (1.7e5 to 1e6 entries), singly and vmapped over 16 poses, and
    slower for masks of 5e3 to 6.6e4 entries vmapped. Both give the same indices.

    **Arguments:**

    - `mask`: bool array of any shape (flattened in row-major order).
    - `size`: the buffer's capacity (static).

    **Returns:** (indices (size,) int32, -1 past the last True entry; valid (size,)
    bool, the slot holds an index; count, int32 scalar: the number of True entries,
    which exceeds `size` when the buffer overflows).
    """
    if mask.size >= WORDS_FROM * size:
        return _compact_words(mask.reshape(-1).astype(bool), size)
    flags = mask.reshape(-1).astype(jnp.int32)
    if flags.shape[0] >= SEARCH_FROM:
        counts = jnp.cumsum(flags)
        slots = jnp.arange(1, size + 1, dtype=counts.dtype)
        found = jnp.searchsorted(counts, slots, side="left", method="scan_unrolled").astype(jnp.int32)
        filled = slots <= counts[-1]
        # `filled`, not index >= 0: XLA's CPU fusion would redo the whole search inside
        # every consumer of the mask (cheap elementwise work is not kept).
        return jnp.where(filled, found, -1), filled, counts[-1]
    position = _blocked_cumsum(flags)
    target = jnp.where(flags > 0, position - 1, size)
    index = jnp.full(size, -1, jnp.int32).at[target].set(jnp.arange(flags.shape[0], dtype=jnp.int32), mode="drop")
    return index, index >= 0, position[-1]
