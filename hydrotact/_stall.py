"""A guard against waits that never end (host).

A computation that is running uses the CPU; one that waits for work that never
comes uses none. A lumped fit of three real stage logs stopped so, for good, after
~40 CPU-s: every XLA thread parked, the main one in `BlockUntilReady` (jaxlib's
batched LAPACK waiting on its own thread pool; hydrotact no longer issues such calls,
see :mod:`hydrotact._linalg`). :class:`StallGuard` watches the process's CPU time
from a thread: when it has not moved for `limit_s` seconds, it calls `on_stall` with
what the process was doing (set with :func:`doing` by the code that knows) and how
long it has waited. The command line prints one line and exits; a stalled job never
waits forever.
"""

import os
import threading
import time


def _limit_from_environment(default: float = 180.0) -> float:
    """HYDROTACT_STALL_S (s), where set to a positive number; else `default`."""
    try:
        value = float(os.environ.get("HYDROTACT_STALL_S", default))
    except ValueError:
        return default
    return value if value > 0.0 else default


STALL_S = _limit_from_environment()  # s without CPU use: a computation that does not move is stuck
_current = ["starting"]


def doing(what: str) -> None:
    """Say what the process is doing now, for the message of a stall."""
    _current[0] = what


def what_now() -> str:
    return _current[0]


def _cpu_seconds() -> float:
    times = os.times()
    return times.user + times.system


class StallGuard:
    """A context manager: while inside, a thread polls the process's CPU time every
    `poll_s` and calls `on_stall(what, seconds)` once if it has not advanced by
    `min_cpu_s` in `limit_s` seconds."""

    def __init__(self, on_stall, limit_s: float = STALL_S, poll_s: float = 5.0, min_cpu_s: float = 0.05):
        self.on_stall, self.limit_s, self.poll_s, self.min_cpu_s = on_stall, float(limit_s), float(poll_s), float(min_cpu_s)
        self._stop = threading.Event()
        self._thread = None

    def _watch(self):
        last_cpu, last_active = _cpu_seconds(), time.monotonic()
        while not self._stop.wait(self.poll_s):
            cpu, now = _cpu_seconds(), time.monotonic()
            if cpu - last_cpu >= self.min_cpu_s:
                last_cpu, last_active = cpu, now
            elif now - last_active >= self.limit_s:
                self.on_stall(what_now(), now - last_active)
                return

    def __enter__(self):
        self._thread = threading.Thread(target=self._watch, name="hydrotact-stall-guard", daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join(timeout=2 * self.poll_s)
        return False
