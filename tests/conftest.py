import jax
import numpy as np
import pytest

# Reference checks run in float64; rank promotion is a bug in our kernels.
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")


@pytest.fixture(autouse=True, scope="session")
def _private_cache(tmp_path_factory):
    """Keep the caches of meshes and unit responses of the test run out of the user's
    home: in `HYDROTACT_TEST_CACHE_DIR` when set (`make test` sets one for all its test
    files: they simulate many of the same poses, and the entries are keyed by their
    inputs' content and written atomically), else in a folder of this session's own.
    Tests that count what is computed or cached set a cache of their own."""
    import os

    shared = os.environ.get("HYDROTACT_TEST_CACHE_DIR")
    os.environ["HYDROTACT_CACHE_DIR"] = shared or str(tmp_path_factory.mktemp("cache"))
    yield


@pytest.fixture
def rng():
    return np.random.default_rng(20261122)
