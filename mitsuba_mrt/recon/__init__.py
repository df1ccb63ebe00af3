"""The reconstruction's numerical stages: numpy and scipy over arrays.

Nothing here imports Mitsuba.  One module per stage: :mod:`.sampling` (the
traced grid), :mod:`.ids` (region ids), :mod:`.edges` (quadtree fill and
Gaussian smoothing), :mod:`.interpolate` (per-id RBF; kernels in
:mod:`.rbf`, :mod:`.rbf_solve`, :mod:`.rbf_fast`), :mod:`.within_region`
(the grid interpolator of the fast modes; its fits in :mod:`.quadric_jit`
where Dr.Jit's LLVM backend runs; noisy grids smoothed first by
:mod:`.smooth`, its kernel in :mod:`.smooth_jit`), :mod:`.compose` (albedo), :mod:`.upsample`
(scene-agnostic baselines) and :mod:`.metrics`.
"""

from .metrics import error_map, paper_error, psnr
from .sampling import SamplePattern, grid_pattern

__all__ = ["SamplePattern", "error_map", "grid_pattern", "paper_error", "psnr"]
