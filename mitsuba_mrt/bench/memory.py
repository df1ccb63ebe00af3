"""Peak memory of one call, for the ``peak_memory_mb`` and ``memory_delta_mb`` columns."""

from __future__ import annotations

import math
import tracemalloc
from contextlib import contextmanager
from dataclasses import dataclass


def _proc_status_kb(field_name: str) -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field_name + ":"):
                return int(line.split()[1])
    raise OSError(f"no {field_name} in /proc/self/status")


@dataclass
class Memory:
    """Peak memory of one call, and its rise over what was resident before, in MB."""

    peak_mb: float = math.nan
    delta_mb: float = math.nan


class MemoryMeter:
    """Peak memory of one call.

    On Linux: the process's peak resident set (``VmHWM``), reset before the
    call by writing 5 to ``/proc/self/clear_refs`` (source ``vmhwm``).
    Elsewhere: the peak of Python's own allocations, numpy's included, from
    :mod:`tracemalloc` (source ``tracemalloc``; Dr.Jit's memory is missed).
    """

    def __init__(self):
        self.source = "tracemalloc"
        try:
            self._reset()
            _proc_status_kb("VmHWM")
            self.source = "vmhwm"
        except (OSError, ValueError):
            pass

    @staticmethod
    def _reset():
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")

    @contextmanager
    def measure(self):
        """Yield a :class:`Memory` that is filled in when the block ends."""
        out = Memory()
        if self.source == "vmhwm":
            self._reset()
            base = _proc_status_kb("VmRSS")
            yield out
            peak = _proc_status_kb("VmHWM")
            out.peak_mb, out.delta_mb = peak / 1024.0, max(peak - base, 0) / 1024.0
        else:
            started = not tracemalloc.is_tracing()
            if started:
                tracemalloc.start()
            tracemalloc.reset_peak()
            base = tracemalloc.get_traced_memory()[0]
            try:
                yield out
                peak = tracemalloc.get_traced_memory()[1]
            finally:
                if started:
                    tracemalloc.stop()
            out.peak_mb, out.delta_mb = peak / 2**20, max(peak - base, 0) / 2**20

