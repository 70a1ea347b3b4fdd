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


def pytest_configure(config):
    """With $HYDROTACT_TEST_PROFILE=FILE, append one JSON line per test phase to FILE:
    its wall and CPU seconds (every thread of this process) and what of it went to
    tracing, lowering and XLA's compiler (and how many programs were compiled or taken
    from the persistent cache). The suite's time is mostly compiling: this says where."""
    import os

    path = os.environ.get("HYDROTACT_TEST_PROFILE")
    if path:
        config.pluginmanager.register(_CompileProfile(path), "hydrotact-compile-profile")


class _CompileProfile:
    EVENTS = {
        "/jax/core/compile/jaxpr_trace_duration": "trace_s",
        "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower_s",
        "/jax/core/compile/backend_compile_duration": "compile_s",
    }

    def __init__(self, path):
        from jax import monitoring

        self.path, self.totals = path, {}
        monitoring.register_event_duration_secs_listener(self._duration)
        monitoring.register_event_listener(self._event)

    def _duration(self, event, duration, **_):
        name = self.EVENTS.get(event)
        if name:
            self.totals[name] = self.totals.get(name, 0.0) + duration
            if name == "compile_s":
                self.totals["programs"] = self.totals.get("programs", 0) + 1

    def _event(self, event, **_):
        if event == "/jax/compilation_cache/cache_hits":
            self.totals["cache_hits"] = self.totals.get("cache_hits", 0) + 1

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(self, item, nextitem):
        import json
        import time

        self.totals = {}
        wall, cpu = time.perf_counter(), time.process_time()
        yield
        record = {"test": item.nodeid, "wall_s": time.perf_counter() - wall, "cpu_s": time.process_time() - cpu, **self.totals}
        with open(self.path, "a") as file:
            file.write(json.dumps(record) + "\n")
