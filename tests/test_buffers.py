"""Fixed-capacity buffers: the one growth rule, the host retry loop, and compaction
against NumPy."""

import dataclasses
import os
import platform
import subprocess
import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hydrotact import HydrotactError, _buffers
from hydrotact._buffers import MAX_BUFFER, AbstractCapacity, compact_indices, run_growing
from hydrotact.contact import Capacity
from hydrotact.taxel import TaxelCapacity


class _Pair(AbstractCapacity):
    first: int = eqx.field(static=True, default=16)
    second: int = eqx.field(static=True, default=64)


@dataclasses.dataclass
class _Result:
    did_overflow: np.ndarray
    needed: np.ndarray


def test_growth_rounds_each_buffer_to_8_to_15_times_a_power_of_two():
    grown = Capacity(256, 256, 4096, 1024).grown_to([300, 10, 4097, 1025])
    assert grown.sizes == (320, 256, 4608, 1152)  # 10 x 32, kept, 9 x 512, 9 x 128
    assert TaxelCapacity(8).grown_to([1000, 0]) == TaxelCapacity(1024)  # 8 x 128
    assert TaxelCapacity(8).grown_to([1025, 0]) == TaxelCapacity(1152)
    for need in range(1, 5000, 37):
        size = TaxelCapacity(0).grown_to([need, 0]).pairs
        assert need <= size <= max(8, need * 9 // 8 + 1), (need, size)
        assert size in {m << k for m in range(8, 16) for k in range(12)} or size == need


def test_growth_never_shrinks_and_doubles_when_nothing_maps():
    capacity = Capacity(4096, 512, 8192, 2048)
    assert capacity.grown_to([10, 600, 10, 10]) == Capacity(4096, 640, 8192, 2048)
    # Counts that fit every buffer although the result overflowed: all grow 2x.
    assert capacity.grown_to([10, 10, 10, 10]) == Capacity(8192, 1024, 16384, 4096)
    assert _Pair().grown_to(np.array([[20, 1], [3, 70]])) == _Pair(20, 72)  # rows: the max of each


def test_growth_past_the_limit_is_a_clear_error(monkeypatch):
    with pytest.raises(HydrotactError, match=f"taxel sampling needs more than {MAX_BUFFER} entries in its pairs buffer"):
        TaxelCapacity().grown_to([MAX_BUFFER + 1, 0])
    assert TaxelCapacity().grown_to([MAX_BUFFER, 0]).pairs == MAX_BUFFER
    monkeypatch.setattr(_buffers, "MAX_BUFFER", 64)
    with pytest.raises(HydrotactError, match="the contact needs more than 64 entries in its polygons buffer"):
        Capacity(16, 16, 32, 32).grown_to([16, 16, 32, 65])
    with pytest.raises(HydrotactError, match="doubling them passes 64"):
        Capacity(16, 16, 48, 32).grown_to([1, 1, 1, 1])


def test_run_growing_retries_until_nothing_overflows():
    calls = []

    def compute(capacity):  # overflows twice, then fits
        calls.append(capacity)
        needs = [np.array([40, 10]), np.array([40, 200]), np.array([40, 200])][len(calls) - 1]
        return _Result(np.asarray(np.any(needs > np.array(capacity.sizes))), needs)

    result, capacity = run_growing(compute, _Pair())
    assert calls == [_Pair(16, 64), _Pair(40, 64), _Pair(40, 208)]
    assert capacity == _Pair(40, 208) and not result.did_overflow


def test_run_growing_takes_the_overflowing_rows_of_a_batch():
    def compute(capacity):
        needed = np.array([[10, 500], [30, 20], [12, 60]])  # row 0 fits only after growing
        return _Result(np.any(needed > np.array(capacity.sizes)[None], axis=1), needed)

    result, capacity = run_growing(compute, _Pair(16, 64))
    assert capacity == _Pair(30, 512)  # max over the overflowing rows 0 and 1: 15 x 2, 8 x 64
    assert not result.did_overflow.any()


@pytest.mark.parametrize("length", [1, 7, 300, 5000, _buffers.SEARCH_FROM + 11])
@pytest.mark.parametrize("density", [0.0, 0.01, 0.3, 1.0])
def test_compaction_matches_flatnonzero(length, density, rng):
    mask = rng.random(length) < density
    expected = np.flatnonzero(mask)
    for size in (1, max(1, len(expected) // 2), len(expected) + 5):
        index, valid, count = jax.jit(compact_indices, static_argnums=1)(jnp.asarray(mask), size)
        kept = min(size, len(expected))
        assert int(count) == len(expected)  # the count exceeds size on overflow
        np.testing.assert_array_equal(np.asarray(index)[:kept], expected[:kept])
        np.testing.assert_array_equal(np.asarray(index)[kept:], -1)
        np.testing.assert_array_equal(np.asarray(valid), np.arange(size) < kept)


@pytest.mark.parametrize(("length", "size"), [(1000, 50), (4096, 128), (1000, 600), (_buffers.SEARCH_FROM + 11, 4096)])
def test_each_compaction_method_vmapped_matches_flatnonzero(length, size, rng):
    """The 32-bit-word method (a mask at least WORDS_FROM times the buffer: the first
    two rows, one of a length that is no multiple of 32), the scatter and the search,
    vmapped as the kernels call them; the set bits at a word's top (bit 31) and a
    whole word set included."""
    masks = rng.random((6, length)) < np.array([0.0, 0.002, 0.02, 0.2, 0.9, 1.0])[:, None]
    masks[2, 31::32] = True
    index, valid, count = jax.jit(jax.vmap(lambda m: compact_indices(m, size)))(jnp.asarray(masks))
    for row, mask in enumerate(masks):
        expected = np.flatnonzero(mask)
        kept = min(size, len(expected))
        assert int(count[row]) == len(expected)
        np.testing.assert_array_equal(np.asarray(index[row])[:kept], expected[:kept])
        np.testing.assert_array_equal(np.asarray(index[row])[kept:], -1)
        np.testing.assert_array_equal(np.asarray(valid[row]), np.arange(size) < kept)


def test_compaction_flattens_a_2d_mask(rng):
    mask = rng.random((25, 40)) < 0.2
    index, _, count = compact_indices(jnp.asarray(mask), 400)
    np.testing.assert_array_equal(np.asarray(index)[: int(count)], np.flatnonzero(mask))


def test_capacity_shrinks_to_a_batch_far_below_it():
    assert Capacity(4096, 512, 8192, 2048).fitted_to([[100, 20, 900, 300], [90, 30, 2000, 400]]) == Capacity(104, 30, 8192, 416)  # pairs: 8192 is not more than 4 x 2048
    assert _Pair(40, 208).fitted_to([12, 60]) == _Pair(40, 208)  # within SHRINK_BELOW of the needs: kept
    assert _Pair(40, 208).fitted_to(np.zeros((0, 2))) == _Pair(40, 208)
    # A batch that needed nothing (no contact) keeps every used buffer at 8 or more, so
    # the next batch, which may touch, still has room to index into; unused (0) stay 0.
    assert Capacity(4096, 512, 8192, 2048).fitted_to([0, 0, 0, 0]) == Capacity(8, 8, 8, 8)
    assert Capacity(512, 0, 0, 1024).fitted_to([0, 0, 0, 0]) == Capacity(8, 0, 0, 8)

    def compute(needs):
        def run(capacity):
            return _Result(np.any(needs > np.array(capacity.sizes)[None], axis=1), needs)

        return run

    _, capacity = run_growing(compute(np.array([[900, 5000], [10, 20]])), _Pair())
    assert capacity == _Pair(960, 5120)
    result, capacity = run_growing(compute(np.array([[30, 50], [10, 20]])), capacity)  # a small batch after the big one
    assert capacity == _Pair(30, 52) and not result.did_overflow.any()
    _, capacity = run_growing(compute(np.array([[200, 50]])), capacity)  # and growing again, never truncated
    assert capacity == _Pair(208, 52)


_MMAPPED_BYTES = """
import ctypes
import numpy as np
import hydrotact  # noqa: F401 (its import sets malloc up)

class Info(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks", "keepcost")]

libc = ctypes.CDLL("libc.so.6")
libc.mallinfo2.restype = Info
before = libc.mallinfo2().hblkhd  # bytes in mmap'd blocks (some from before the import)
block = np.ones(64 * 2**20 // 8)  # 64 MB, above glibc's largest mmap threshold
print(libc.mallinfo2().hblkhd - before)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux") or platform.libc_ver()[0] != "glibc", reason="glibc's malloc only")
def test_importing_hydrotact_keeps_large_blocks_in_the_heap():
    """XLA's per-call temporaries come from malloc; with hydrotact imported, a 64 MB
    block comes from the heap (kept, reused warm), not from fresh mmap'd pages, unless
    HYDROTACT_MALLOC=system (benchmarks/RESULTS.md, issue 48)."""
    def mmapped(**env):
        out = subprocess.run([sys.executable, "-c", _MMAPPED_BYTES], capture_output=True, text=True, env={**os.environ, **env}, timeout=120, check=True)
        return int(out.stdout.split()[-1])

    assert mmapped(HYDROTACT_MALLOC="") == 0
    assert mmapped(HYDROTACT_MALLOC="system") >= 64 * 2**20
