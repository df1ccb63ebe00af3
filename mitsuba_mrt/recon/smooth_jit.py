"""The grid smoothing of :mod:`.smooth` as one Dr.Jit LLVM kernel.

:func:`mitsuba_mrt.recon.smooth.smooth_grid` in numpy makes a dozen passes
over the grid per neighbour; here each sample reads its 3 x 3
neighbourhood once, in a single vectorised kernel on all cores.  The
arithmetic is the numpy version's, operation for operation and in the same
order, except for the exponential (Dr.Jit's own): results agree to a few
units in the last place.  Grid size and strength are kernel inputs, so a
grid of another size or another strength replays the kernel.  It is used
where Dr.Jit's LLVM backend is safe to start
(:func:`mitsuba_mrt.recon.llvm_arrays.available`).
"""

from __future__ import annotations

import numpy as np

from .llvm_arrays import aligned


def smooth_grid_jit(grid_ids: np.ndarray, values: np.ndarray, noise: np.ndarray,
                    usable: np.ndarray, scale: float) -> np.ndarray:
    """:func:`mitsuba_mrt.recon.smooth.smooth_grid`'s weighted means,
    float64 (nr, nc, C); ``usable`` (nr, nc) bool is the samples that are
    neither fixed nor left out, ``scale`` is ``-1 / (2 strength^2 C)``.
    """
    import drjit as dr
    from drjit.llvm import Bool, Float64, Int32, UInt64

    nr, nc, channels = values.shape
    ids = aligned(UInt64, np.asarray(grid_ids, dtype=np.int64).view(np.uint64), np.uint64)
    flat_values = aligned(Float64, values, np.float64)
    flat_noise = aligned(Float64, noise, np.float64)
    usable = aligned(Bool, usable, np.bool_)
    rows, cols = dr.opaque(Int32, nr), dr.opaque(Int32, nc)
    depth = dr.opaque(Int32, channels)
    scale = dr.opaque(Float64, scale)

    index = dr.arange(Int32, nr * nc)
    y = index // cols
    x = index - y * cols
    own_id = dr.gather(UInt64, ids, index)
    own = [dr.gather(Float64, flat_values, index * depth + c) for c in range(channels)]
    own_noise = [dr.gather(Float64, flat_noise, index * depth + c) for c in range(channels)]
    level = own_noise[0]
    loudest = own_noise[0]
    for n in own_noise[1:]:
        level = level + n
        loudest = dr.maximum(loudest, n)
    level = level / channels
    total = list(own)
    weight = Float64(1.0)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if not (dy or dx):
                continue
            ny, nx = y + dy, x + dx
            inside = (ny >= 0) & (ny < rows) & (nx >= 0) & (nx < cols)
            there = dr.select(inside, ny * cols + nx, index)
            # a pair's exponent: the sum over channels of d^2 / combined noise
            # (0 for equal noise-free samples, else never averaged)
            exponent = Float64(0.0)
            values_there, noise_there = [], []
            for c in range(channels):
                v = dr.gather(Float64, flat_values, there * depth + c)
                n = dr.gather(Float64, flat_noise, there * depth + c)
                d = own[c] - v
                combined = own_noise[c] + n
                silent = dr.select(d == 0.0, 0.0, np.inf)
                exponent = exponent + dr.select(combined > 0.0, (d * d) / combined, silent)
                values_there.append(v)
                noise_there.append(n)
            level_there = noise_there[0]
            for n in noise_there[1:]:
                level_there = level_there + n
            level_there = level_there / channels
            same = inside & (dr.gather(UInt64, ids, there) == own_id) & \
                dr.gather(Bool, usable, there)
            w = dr.select(same, dr.exp(exponent * scale), 0.0)
            w = w * dr.select(level_there > level, level / level_there, 1.0)
            for c in range(channels):
                total[c] = total[c] + values_there[c] * w
            weight = weight + w
    keep = ~dr.gather(Bool, usable, index) | (loudest <= 0.0)
    out = [dr.select(keep, own[c], total[c] / weight) for c in range(channels)]
    dr.eval(*out)
    return np.stack([np.asarray(v) for v in out], axis=1).reshape(nr, nc, channels)
