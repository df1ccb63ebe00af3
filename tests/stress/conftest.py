"""Hypothesis profiles of the stress suite and its summary table.

``fast`` (default): deterministic, a few cases per property and mode, so
the whole folder runs in about a minute on two cores.  ``thorough``
(``MITSUBA_MRT_STRESS=thorough``): 1000 examples per property and mode;
failures are counted rather than stopping each test at the first, and a
table of cases and failures per property and mode ends the run.  ``repro``:
as many examples, but each test stops at its first failure and shrinks it
to a minimal example (a standalone snippet is printed with it).
"""

from __future__ import annotations

import os

from hypothesis import HealthCheck, settings

from .stress_support import TALLIES

_COMMON = dict(deadline=None, database=None, print_blob=False,
               suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                      HealthCheck.filter_too_much])

settings.register_profile("fast", max_examples=6, derandomize=True, **_COMMON)
settings.register_profile("thorough",
                          max_examples=int(os.environ.get("MITSUBA_MRT_STRESS_EXAMPLES", 1000)),
                          **_COMMON)
# as many examples as thorough, but stop at the first failure and shrink it
settings.register_profile("repro", max_examples=int(os.environ.get("MITSUBA_MRT_STRESS_EXAMPLES", 1000)),
                          **_COMMON)
settings.load_profile(os.environ.get("MITSUBA_MRT_STRESS", "fast"))


def pytest_terminal_summary(terminalreporter):
    if os.environ.get("MITSUBA_MRT_STRESS") != "thorough" or not TALLIES:
        return
    write = terminalreporter.write_line
    write("")
    write("stress summary: cases run / failing cases (worst measure; failure kinds)")
    props = list(dict.fromkeys(p for p, _ in TALLIES))  # in the order they ran
    modes = sorted({m for _, m in TALLIES}, key=["paper", "fast", "refine", "idpass"].index)
    write(f"{'property':<20}" + "".join(f"{m:>16}" for m in modes))
    for prop in props:
        cells = []
        for mode in modes:
            t = TALLIES.get((prop, mode))
            cells.append(f"{t.failures:>6}/{t.cases:<6}" if t else "-")
        write(f"{prop:<20}" + "".join(f"{c:>16}" for c in cells))
    write("")
    for (prop, mode), t in TALLIES.items():
        if t.failures:
            kinds = ", ".join(f"{k} x{n}" for k, n in sorted(t.kinds.items(), key=lambda kv: -kv[1]))
            write(f"{prop}/{mode}: worst {t.worst:.3g}; {kinds}")
