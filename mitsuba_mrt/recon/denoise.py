"""Denoising the traced grid before it is reconstructed (``denoise="oidn"``).

The grid's pixels form a small image (grid rows x grid columns); a
denoiser sees it with the trace's albedo and normals as guides.
"""

from __future__ import annotations

import numpy as np

from ..errors import MRTError


def denoise_grid(radiance: np.ndarray, albedo: np.ndarray | None = None,
                 normal: np.ndarray | None = None, denoiser: str = "oidn") -> np.ndarray:
    """The grid image ``radiance`` (rows, columns, 3), denoised."""
    raise MRTError(f"denoiser {denoiser!r} is not available yet")
