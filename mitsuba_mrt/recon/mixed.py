"""Edge pixels that show two surfaces, unmixed by their albedo (mode ``idpass``).

A pixel on an edge sees two surfaces: its radiance is ``c * a1 * E1 +
(1 - c) * a2 * E2`` for the share ``c`` of its footprint on its own region
(the surface its centre sees), the two regions' albedos ``a`` and
irradiances ``E``.  Interpolation within ids gives it its own region's
irradiance alone, ``A * E1`` for its albedo ``A``.  The full-resolution
albedo of the id pass is that same mix, ``A = c * a1 + (1 - c) * a2``, so
where both regions are locally of one colour and the colours differ, the
share can be read from it: :func:`unmix_edges`.

A pixel is left as it is unless all of these hold: exactly one other id in
its 3 x 3 neighbourhood; in its 5 x 5 neighbourhood, at least
:data:`SIDE_PIXELS` pixels off the edge on each side, and each side's
albedos within :data:`FIT_TOLERANCE` of the colours' distance from their
median (a texture is not a mix); every albedo involved above
:data:`DARKEST` in every channel (nothing to read from black, and emitters
and the background are not demodulated); colours :data:`MIN_CONTRAST`
apart; the pixel's albedo within :data:`FIT_TOLERANCE` of the line between
them; and a share of its own region below :data:`MAX_SHARE`.  The result
is then between the two regions' values, ``a1 * E1`` and ``a2 * E2``,
channel by channel: the one place where a reconstructed pixel takes light
from a region other than its own, as the surfaces in its footprint do.
"""

from __future__ import annotations

import numpy as np

from .compose import safe_albedo
from .metrics import edge_mask

#: Least albedo, per channel, of the pixels unmixed and of their two regions.
DARKEST = 0.01
#: Least Euclidean distance between the two regions' albedos (RGB).
MIN_CONTRAST = 0.05
#: Largest distance, as a share of the two albedos' distance, of the pixel's
#: albedo from the line between them, and of each side's albedos from their median.
FIT_TOLERANCE = 0.15
#: Fewest pixels off the edge on each side in the 5 x 5 neighbourhood: one
#: colour is not told from a texture by fewer.
SIDE_PIXELS = 3
#: A pixel whose albedo gives its own region this share or more is left alone.
MAX_SHARE = 0.98

_OFFSETS = np.array([(dy, dx) for dy in range(-2, 3) for dx in range(-2, 3)])
_NEAR = (np.abs(_OFFSETS) <= 1).all(axis=1)  # the 3 x 3 part of the 5 x 5 window


def unmix_edges(irradiance: np.ndarray, albedo: np.ndarray, ids: np.ndarray,
                keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Radiance ``irradiance * albedo``, with the edge pixels that mix two regions unmixed.

    Parameters
    ----------
    irradiance : ndarray, shape (height, width, 3)
        Each pixel's own region's irradiance (radiance over its safe albedo).
    albedo : ndarray, shape (height, width, 3)
        The albedo of every pixel over its footprint, as traced (not made safe).
    ids : ndarray of int, shape (height, width)
        The region of every pixel's centre.
    keep : ndarray of bool, shape (height, width)
        Pixels left as they are (the traced ones).

    Returns
    -------
    image : ndarray, shape (height, width, 3), float64
    unmixed : ndarray of bool, shape (height, width)

    Examples
    --------
    >>> ids = np.array([[1, 1, 2, 2]] * 5)
    >>> albedo = np.where(ids[..., None] == 1, 0.8, 0.2) * np.ones(3)
    >>> albedo[:, 1] = 0.5             # half on each: its centre is on id 1
    >>> irradiance = np.where(ids[..., None] == 1, 1.0, 3.0) * np.ones(3)
    >>> image, unmixed = unmix_edges(irradiance, albedo, ids, np.zeros((5, 4), bool))
    >>> float(image[2, 1, 0])          # 0.5 * 0.8 * 1 + 0.5 * 0.2 * 3, not 0.5 * 1
    0.7
    """
    irradiance = np.asarray(irradiance, dtype=np.float64)
    albedo = np.asarray(albedo, dtype=np.float64)
    image = irradiance * safe_albedo(albedo)
    unmixed = np.zeros(ids.shape, dtype=bool)
    edge = edge_mask(ids)
    ys, xs = np.nonzero(edge & ~keep)
    if not len(ys):
        return image, unmixed
    pad = ((2, 2), (2, 2))
    win_y, win_x = ys[:, None] + 2 + _OFFSETS[:, 0], xs[:, None] + 2 + _OFFSETS[:, 1]
    win_ids = np.pad(ids, pad, constant_values=-1)[win_y, win_x]          # (n, 25)
    on_edge = np.pad(edge, pad, constant_values=True)[win_y, win_x]
    win_albedo = np.pad(albedo, pad + ((0, 0),))[win_y, win_x]           # (n, 25, 3)
    win_irr = np.pad(irradiance, pad + ((0, 0),))[win_y, win_x]

    own = ids[ys, xs][:, None]
    near = win_ids[:, _NEAR]
    foreign = (near != own) & (near >= 0)
    other = np.where(foreign, near, np.iinfo(near.dtype).max).min(axis=1)
    single = foreign.any(axis=1) & (np.where(foreign, near, other[:, None]) == other[:, None]).all(1)
    mine = (win_ids == own) & ~on_edge
    theirs = (win_ids == other[:, None]) & ~on_edge
    ok = single & (mine.sum(axis=1) >= SIDE_PIXELS) & (theirs.sum(axis=1) >= SIDE_PIXELS)

    # the median albedo of each side, off the edge, and how far its albedos spread
    def side(mask):
        values = np.where(mask[ok][..., None], win_albedo[ok], np.nan)
        middle = np.nanmedian(values, axis=1)
        spread = np.nanmax(np.linalg.norm(values - middle[:, None], axis=2), axis=1)
        return middle, spread

    index = np.flatnonzero(ok)
    a1, spread1 = side(mine)
    a2, spread2 = side(theirs)
    pixel = albedo[ys[index], xs[index]]
    d = a1 - a2
    squared = np.einsum("nc,nc->n", d, d)
    distance = np.sqrt(squared)
    along = np.einsum("nc,nc->n", pixel - a2, d)
    share = np.clip(np.divide(along, squared, out=np.zeros_like(along), where=squared > 0),
                    0.0, 1.0)
    off_line = np.linalg.norm(pixel - (share[:, None] * a1 + (1 - share[:, None]) * a2), axis=1)
    good = ((np.minimum(np.minimum(a1, a2), pixel).min(axis=1) > DARKEST)
            & (distance >= MIN_CONTRAST) & (share < MAX_SHARE)
            & (off_line <= FIT_TOLERANCE * distance)
            & (np.maximum(spread1, spread2) <= FIT_TOLERANCE * distance))
    index, share, a1, a2 = index[good], share[good][:, None], a1[good], a2[good]
    if not len(index):
        return image, unmixed
    # the other region's irradiance: the mean of its pixels among the 3 x 3
    theirs_near = (win_ids[index][:, _NEAR] == other[index][:, None])[..., None]
    e2 = (win_irr[index][:, _NEAR] * theirs_near).sum(axis=1) / theirs_near.sum(axis=1)
    y, x = ys[index], xs[index]
    image[y, x] = share * a1 * irradiance[y, x] + (1 - share) * a2 * e2
    unmixed[y, x] = True
    return image, unmixed
