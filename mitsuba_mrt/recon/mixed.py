"""Edge pixels that show two surfaces, unmixed by their albedo (mode ``idpass``).

A pixel on an edge sees two surfaces: its radiance is ``c * a1 * E1 +
(1 - c) * a2 * E2`` for the share ``c`` of its footprint on its own region
(the surface its centre sees), the two regions' albedos ``a`` and
irradiances ``E``.  Interpolation within ids gives it its own region's
irradiance alone, ``A * E1`` for its albedo ``A``.  The full-resolution
albedo of the id pass is that same mix, ``A = c * a1 + (1 - c) * a2``, so
where both regions are locally of one colour and the colours differ, the
share can be read from it: :func:`unmix_edges`.

Each pixel is read across its edge: along the first of the four axis
directions in which the next three pixels are the other region's and the
two behind it its own, the two pixels off the edge on each side (two and
three steps out on the other side, one and two back on its own) give the
side's colour.  A pixel is left as it is unless all of these hold: exactly
one other id in its 3 x 3 neighbourhood; such a direction; each side's two
albedos within :data:`FIT_TOLERANCE` of the colours' distance of each other
(a texture is not a mix); every albedo involved above :data:`DARKEST` in
every channel (nothing to read from black, and emitters and the background
are not demodulated); colours :data:`MIN_CONTRAST` apart; the pixel's
albedo within :data:`FIT_TOLERANCE` of the line between them; and a share
of its own region below :data:`MAX_SHARE`.  The other region's irradiance
is its neighbour's in that direction.  The result is then between the two
regions' values, ``a1 * E1`` and ``a2 * E2``, channel by channel: the one
place where a reconstructed pixel takes light from a region other than its
own, as the surfaces in its footprint do.
"""

from __future__ import annotations

import numpy as np

from .compose import safe_albedo
from .metrics import edge_mask

#: Least albedo, per channel, of the pixels unmixed and of their two regions.
DARKEST = 0.01
#: Least Euclidean distance between the two regions' albedos (RGB).
MIN_CONTRAST = 0.05
#: Largest distance, as a share of the two colours' distance, of the pixel's
#: albedo from the line between them, and between the two albedos of a side.
FIT_TOLERANCE = 0.15
#: A pixel whose albedo gives its own region this share or more is left alone.
MAX_SHARE = 0.98

_NEAR = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dy or dx]
_DIRECTIONS = [(0, 1), (0, -1), (1, 0), (-1, 0)]


def unmix_edges(irradiance: np.ndarray, albedo: np.ndarray, ids: np.ndarray,
                keep: np.ndarray, modulation: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
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
    modulation : ndarray, shape (height, width, 3), optional
        What ``irradiance`` is multiplied by where a pixel is not unmixed
        (:func:`~.compose.pixel_modulation`), float64, overwritten with the
        image; default: the albedo, 1 where it is at most
        :data:`~.compose.ALBEDO_EPS`.

    Returns
    -------
    image : ndarray, shape (height, width, 3), float64
    unmixed : ndarray of bool, shape (height, width)

    Examples
    --------
    >>> ids = np.array([[1, 1, 1, 1, 2, 2, 2, 2]] * 5)
    >>> albedo = np.where(ids[..., None] == 1, 0.8, 0.2) * np.ones(3)
    >>> albedo[:, 3] = 0.5             # half on each: its centre is on id 1
    >>> irradiance = np.where(ids[..., None] == 1, 1.0, 3.0) * np.ones(3)
    >>> image, unmixed = unmix_edges(irradiance, albedo, ids, np.zeros((5, 8), bool))
    >>> float(image[2, 3, 0])          # 0.5 * 0.8 * 1 + 0.5 * 0.2 * 3, not 0.5 * 1
    0.7
    """
    irradiance = np.asarray(irradiance, dtype=np.float64)
    albedo = np.asarray(albedo, dtype=np.float64)
    # the product goes into a new array, or into ``modulation``
    image = safe_albedo(albedo) if modulation is None else np.asarray(modulation, np.float64)
    image *= irradiance
    unmixed = np.zeros(ids.shape, dtype=bool)
    ys, xs = np.nonzero(edge_mask(ids) & ~keep)
    if not len(ys):
        return image, unmixed
    height, width = ids.shape

    def id_at(dy, dx):  # the ids dy, dx steps from each edge pixel (-1 off the image)
        y, x = ys + dy, xs + dx
        inside = (y >= 0) & (y < height) & (x >= 0) & (x < width)
        return np.where(inside, ids[np.clip(y, 0, height - 1), np.clip(x, 0, width - 1)], -1)

    own = ids[ys, xs]
    near = np.stack([id_at(dy, dx) for dy, dx in _NEAR], axis=1)
    foreign = (near != own[:, None]) & (near >= 0)
    other = np.where(foreign, near, np.iinfo(near.dtype).max).min(axis=1)
    single = foreign.any(axis=1) & (np.where(foreign, near, other[:, None])
                                    == other[:, None]).all(axis=1)
    sy, sx = np.zeros(len(ys), dtype=np.int64), np.zeros(len(ys), dtype=np.int64)
    found = np.zeros(len(ys), dtype=bool)  # a direction that reads across
    for dy, dx in _DIRECTIONS:
        across = (single & ~found & (id_at(-2 * dy, -2 * dx) == own)
                  & (id_at(-dy, -dx) == own) & (id_at(dy, dx) == other)
                  & (id_at(2 * dy, 2 * dx) == other) & (id_at(3 * dy, 3 * dx) == other))
        sy[across], sx[across] = dy, dx
        found |= across
    index = np.flatnonzero(found)
    ys, xs, sy, sx = ys[index], xs[index], sy[index], sx[index]

    def colour(m):  # the albedo m steps across the edge (on the image: the ids above say so)
        return albedo[ys + m * sy, xs + m * sx]

    mine = colour(-1), colour(-2)
    theirs = colour(2), colour(3)
    a1, a2 = (mine[0] + mine[1]) / 2, (theirs[0] + theirs[1]) / 2
    pixel = colour(0)
    d = a1 - a2
    squared = np.einsum("nc,nc->n", d, d)
    distance = np.sqrt(squared)
    along = np.einsum("nc,nc->n", pixel - a2, d)
    share = np.clip(np.divide(along, squared, out=np.zeros_like(along), where=squared > 0),
                    0.0, 1.0)
    off_line = np.linalg.norm(pixel - (share[:, None] * a1 + (1 - share[:, None]) * a2), axis=1)
    spread = np.maximum(np.linalg.norm(mine[0] - mine[1], axis=1),
                        np.linalg.norm(theirs[0] - theirs[1], axis=1))
    darkest = np.minimum.reduce([mine[0], mine[1], theirs[0], theirs[1], pixel]).min(axis=1)
    good = ((darkest > DARKEST) & (distance >= MIN_CONTRAST) & (share < MAX_SHARE)
            & (off_line <= FIT_TOLERANCE * distance) & (spread <= FIT_TOLERANCE * distance))
    if not good.any():
        return image, unmixed
    y, x, sy, sx = ys[good], xs[good], sy[good], sx[good]
    share, a1, a2 = share[good][:, None], a1[good], a2[good]
    e2 = irradiance[y + sy, x + sx]
    image[y, x] = share * a1 * irradiance[y, x] + (1 - share) * a2 * e2
    unmixed[y, x] = True
    return image, unmixed
