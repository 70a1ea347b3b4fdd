import jax
import numpy as np
import pytest

# Reference checks run in float64; rank promotion is a bug in our kernels.
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")


@pytest.fixture(autouse=True, scope="session")
def _private_cache(tmp_path_factory):
    """Keep the cache of meshes and elastic fields out of the user's home: one per
    session, or the one `make test` shares across its test files
    ($HYDROTACT_TEST_CACHE_DIR, made anew each run; its entries are written atomically).
    Tests that must see a cold cache set their own."""
    import os

    shared = os.environ.get("HYDROTACT_TEST_CACHE_DIR")
    os.environ["HYDROTACT_CACHE_DIR"] = shared or str(tmp_path_factory.mktemp("cache"))
    yield


@pytest.fixture
def rng():
    return np.random.default_rng(20261122)
