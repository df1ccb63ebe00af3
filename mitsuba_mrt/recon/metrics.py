"""Stage 6: how far a reconstruction is from the full render.

All metrics compare colours clipped to [0, 1], as the report does.
"""

from __future__ import annotations

import numpy as np

from ..errors import MRTError


def _pair(image: np.ndarray, reference: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    image = np.asarray(image, dtype=np.float64)
    reference = np.asarray(reference, dtype=np.float64)
    if image.shape != reference.shape:
        raise MRTError(f"image shape {image.shape} differs from reference shape {reference.shape}")
    if not (np.isfinite(image).all() and np.isfinite(reference).all()):
        raise MRTError("images to compare must be finite (NaN or Inf radiance?)")
    return np.clip(image, 0.0, 1.0), np.clip(reference, 0.0, 1.0)


def error_map(image: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Per-pixel ``sum_c |image - reference| / 3`` (the report's error map).

    Examples
    --------
    >>> error_map(np.full((1, 1, 3), 0.5), np.zeros((1, 1, 3)))
    array([[0.5]])
    """
    a, b = _pair(image, reference)
    return np.abs(a - b).sum(axis=-1) / a.shape[-1]


def paper_error(image: np.ndarray, reference: np.ndarray) -> float:
    """The report's error: ``sum_{x,y,c} |image - reference| / (3 W H)``.

    Examples
    --------
    >>> paper_error(np.ones((2, 2, 3)), np.zeros((2, 2, 3)))
    1.0
    """
    return float(error_map(image, reference).mean())


def psnr(image: np.ndarray, reference: np.ndarray) -> float:
    """Peak signal-to-noise ratio in dB (peak 1); ``inf`` for identical images.

    Examples
    --------
    >>> round(psnr(np.full((2, 2, 3), 0.1), np.zeros((2, 2, 3))), 6)
    20.0
    """
    a, b = _pair(image, reference)
    mse = float(np.mean((a - b) ** 2))
    return float("inf") if mse == 0.0 else float(-10.0 * np.log10(mse))


def edge_mask(ids: np.ndarray) -> np.ndarray:
    """Pixels whose id differs from one of their 4-neighbours' (both sides of an edge).

    Errors on these pixels measure how well a reconstruction finds edges.

    Examples
    --------
    >>> edge_mask(np.array([[1, 1, 2]])).astype(int)
    array([[0, 1, 1]])
    """
    ids = np.asarray(ids)
    edge = np.zeros(ids.shape, dtype=bool)
    for a, b in ((np.s_[:, 1:], np.s_[:, :-1]), (np.s_[1:], np.s_[:-1])):
        differ = ids[a] != ids[b]
        edge[a] |= differ
        edge[b] |= differ
    return edge


def relative_error(squared: np.ndarray, reference: np.ndarray) -> float:
    """Root of the mean of ``squared`` (n, 3) over the pixels a display shows
    unclipped (``reference`` below 1), over the mean square of ``reference``
    there: ``auto``'s relative RMS error, of squared errors that may have been
    estimated (a noise subtracted: a negative mean counts as 0).

    ``reference`` should be free of fireflies (a denoised image): a noisy
    one leaves its noisiest pixels out, and the noise with them.

    Examples
    --------
    >>> relative_error(np.full((2, 3), 0.01), np.full((2, 3), 0.5))
    0.2
    """
    shown = (reference <= 1.0).all(axis=1)
    if not shown.any():
        return 0.0
    power = max(float(np.mean(reference[shown] ** 2)), 1e-12)
    return float(np.sqrt(max(float(np.mean(squared[shown])), 0.0) / power))
