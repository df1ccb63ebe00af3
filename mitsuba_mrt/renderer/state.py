"""The package's caches for the life of the process, and clearing them.

A few modules keep what is costly to make and the same each time it is
made: the trace's recorded kernels and the Mitsuba objects held for them,
a filter or integrator made once per variant, the tables of the pixel
filters, the OIDN device and filters, interpolation weights, and what the
last renders took (OIDN's calls, ``auto``'s first round under a time
limit and its passes' last OIDN call, the passes' launches, the grid
probe's recording, a preview's stages after its grid, the checked MRT
plans).  None of them
changes a result, except that ``auto`` plans a time limit from those
times.  :func:`clear_caches` drops them all, to free what they hold or to
time a first call again; docs/ARCHITECTURE.md (Process-wide state) lists
each, with the state that is not a cache and stays.
"""

from __future__ import annotations

from ..recon import denoise, llvm_arrays, rbf_fast
from . import auto_limit, develop, guides, kept_plans, pixel_filter, replay


def clear_caches() -> None:
    """Drop every cache the package keeps for the process; each is made anew on next use.

    Later renders give the same images; the first of each kind records its
    kernels again (Dr.Jit's own cache of compiled kernels is not cleared).
    """
    replay.clear_recordings()
    auto_limit._first_round_s.clear()
    auto_limit._final_denoise_s.clear()
    auto_limit._launch_costs.clear()
    auto_limit._memory_keys.clear()
    auto_limit._probe_recording_s.clear()
    auto_limit._probe_execute.clear()
    auto_limit._preview_after_s.clear()
    auto_limit._preview_rate.clear()
    kept_plans.clear()
    develop._BOX_FILTERS.clear()
    guides._integrators.clear()
    pixel_filter._TABLES.clear()
    pixel_filter._WEIGHTS.clear()
    denoise.release()
    rbf_fast._tensor_weights.cache_clear()
    rbf_fast._near_table.cache_clear()
    llvm_arrays.available.cache_clear()
