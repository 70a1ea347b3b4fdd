import jax
import numpy as np
import pytest

# Reference checks run in float64; rank promotion is a bug in our kernels.
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")


@pytest.fixture(autouse=True, scope="session")
def _private_cache(tmp_path_factory):
    """Keep the mesh cache of the test run out of the user's home."""
    import os

    os.environ["HYDROTACT_CACHE_DIR"] = str(tmp_path_factory.mktemp("cache"))
    yield


@pytest.fixture
def rng():
    return np.random.default_rng(20261122)
