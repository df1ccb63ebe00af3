"""Stage 5: from interpolated irradiance back to colour.

The MRT interpolates irradiance, not colour (the report's Section 4): the
trace's radiance is divided by the surface albedo, interpolated, and
multiplied back.  Where an id's albedo is zero in a channel (a mirror, the
background), or its light does not follow its albedo (glass that shows the
sky), that channel of the id is interpolated as radiance
(:func:`radiance_channels`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .ids import run_starts

#: Albedo below which a channel is not demodulated.
ALBEDO_EPS = 1e-6
#: The share of an id's samples with light but no albedo above which the id
#: is interpolated as radiance (:func:`radiance_channels`).
LIT_SHARE = 0.05


def safe_albedo(albedo: np.ndarray) -> np.ndarray:
    """The albedo, with 1 wherever a channel is too small to divide by."""
    albedo = np.asarray(albedo, dtype=np.float64)
    return np.where(albedo > ALBEDO_EPS, albedo, 1.0)


def radiance_channels(sample_ids: np.ndarray, albedo: np.ndarray,
                      radiance: np.ndarray | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ids, inverse, plain): the samples' distinct ids, sorted, each
    sample's index among them, and for each id and channel whether it is
    interpolated as radiance, not demodulated: where at most half the id's
    samples have an albedo above :data:`ALBEDO_EPS` in the channel (a
    mirror, an emitter, a black surface, the background), or, given the
    samples' ``radiance``, where more than :data:`LIT_SHARE` of them have
    light but no albedo (glass that shows a surface and the sky: its light
    does not follow its albedo).

    A sample at the edge of such an id whose footprint catches a little of
    a brighter neighbour has a tiny albedo: divided by it, its value would
    be hundreds of times its id's others, taken as radiance, and an
    interpolation of both would light the whole neighbourhood.

    Examples
    --------
    >>> ids, inverse, plain = radiance_channels(np.array([4, 4, 4, 7]),
    ...                                         np.array([[0.0], [0.0], [0.02], [0.5]]))
    >>> ids.tolist(), inverse.tolist(), plain[:, 0].tolist()
    ([4, 7], [0, 0, 0, 1], [True, False])
    >>> glass = np.array([[0.3]] * 18 + [[0.0]] * 2)   # 2 of 20 show the sky
    >>> radiance_channels(np.zeros(20, int), glass, np.ones((20, 1)))[2].tolist()
    [[True]]
    """
    albedo = np.asarray(albedo)
    sample_ids = np.asarray(sample_ids).ravel()
    if (sample_ids.dtype.kind in "iu" and len(sample_ids)
            and 0 <= sample_ids.min() and sample_ids.max() < 4 * len(sample_ids)):
        # small non-negative ids (ranks): their own indices, without a sort
        inverse = sample_ids.astype(np.intp)
        counts = np.bincount(inverse)
        ids = np.flatnonzero(counts)
        counts, inverse = counts[ids], np.searchsorted(ids, inverse)
    else:
        ids, inverse, counts = np.unique(sample_ids, return_inverse=True, return_counts=True)
        inverse = inverse.ravel()

    def per_id(flags):  # how many samples of each id have the flag, per channel
        return np.stack([np.bincount(inverse, weights=f, minlength=len(ids)) for f in flags.T],
                        axis=1)
    dark = albedo <= ALBEDO_EPS
    plain = 2 * per_id(~dark) <= counts[:, None]
    if radiance is not None:
        plain |= per_id(dark & (np.asarray(radiance) > ALBEDO_EPS)) > LIT_SHARE * counts[:, None]
    return ids, inverse, plain


def division_albedo(albedo: np.ndarray, plain: np.ndarray) -> np.ndarray:
    """The albedo each sample's radiance is divided by (and multiplied back
    by): :func:`safe_albedo`, and 1 in the channels its id takes as radiance
    (``plain``, per sample: :func:`radiance_channels`' ``plain[inverse]``).

    Examples
    --------
    >>> division_albedo(np.array([[0.0], [0.02], [0.5]]), np.array([[True], [True], [False]]))[:, 0]
    array([1. , 1. , 0.5])
    """
    albedo = np.asarray(albedo, dtype=np.float64)
    return np.where(plain | (albedo <= ALBEDO_EPS), 1.0, albedo)


def pixel_modulation(id_map: np.ndarray, albedo: np.ndarray, ids: np.ndarray,
                     plain: np.ndarray) -> np.ndarray:
    """(height, width, channels): what each pixel's interpolated value is
    multiplied by, its own ``albedo`` however small, and 1 in the channels
    its id takes as radiance (``ids``, ``plain``: :func:`radiance_channels`).
    A pixel whose id no sample carries is taken as demodulated (mode
    ``idpass`` traces it anyway).

    Examples
    --------
    >>> ids, _, plain = radiance_channels(np.array([4, 4, 7]), np.array([[0.0], [0.0], [0.5]]))
    >>> pixel_modulation(np.array([[4, 7, 7]]), np.array([[[0.01], [0.4], [0.0]]]), ids, plain)[0, :, 0]
    array([1. , 0.4, 0. ])
    """
    out = np.array(albedo, dtype=np.float64)
    some = plain.any(axis=1)
    if not some.any():
        return out
    if plain[some].all():  # (the usual case: plain in every channel)
        out[np.isin(id_map, ids[some])] = 1.0
        return out
    for c in range(plain.shape[1]):
        out[..., c][np.isin(id_map, ids[plain[:, c]])] = 1.0
    return out


def demodulate(radiance: np.ndarray, albedo: np.ndarray) -> np.ndarray:
    """Irradiance-like values: ``radiance / safe_albedo(albedo)``.

    Examples
    --------
    >>> demodulate(np.array([[0.25, 0.5, 0.0]]), np.array([[0.5, 0.5, 0.0]]))
    array([[0.5, 1. , 0. ]])
    """
    return np.asarray(radiance, dtype=np.float64) / safe_albedo(albedo)


def region_values(id_map: np.ndarray, sample_ids: np.ndarray, sample_values: np.ndarray,
                  how: str = "mean", fill=0.0) -> np.ndarray:
    """Give every pixel a value of its region's samples.

    Parameters
    ----------
    id_map : ndarray of int, shape (height, width)
    sample_ids : ndarray of int, shape (n,)
    sample_values : ndarray, shape (n,) or (n, channels)
    how : {'mean', 'first'}
        Mean of the region's samples, or the value of its first sample.
    fill : scalar
        Value for ids that no sample carries.

    Examples
    --------
    >>> region_values(np.array([[1, 2]]), np.array([1, 1]), np.array([0.2, 0.4]))
    array([[0.3, 0. ]])
    """
    sample_values = np.asarray(sample_values)
    if len(sample_values) == 0:
        return np.full(np.shape(id_map) + sample_values.shape[1:], fill,
                       dtype=np.result_type(sample_values.dtype, np.asarray(fill).dtype))
    regions, first, inverse = np.unique(np.asarray(sample_ids), return_index=True,
                                        return_inverse=True)
    if how == "mean":
        sums = np.zeros((len(regions),) + sample_values.shape[1:])
        np.add.at(sums, inverse, sample_values)
        counts = np.bincount(inverse, minlength=len(regions))
        table = sums / counts.reshape((-1,) + (1,) * (sample_values.ndim - 1))
    elif how == "first":
        table = sample_values[first]
    else:
        raise ValueError(f"how must be 'mean' or 'first', got {how!r}")
    pos = np.clip(np.searchsorted(regions, id_map), 0, len(regions) - 1)
    found = (regions[pos] == id_map).reshape(id_map.shape + (1,) * (sample_values.ndim - 1))
    return np.where(found, table[pos], np.asarray(fill, dtype=table.dtype))


#: Queries of fewer points than this run on one thread: scipy starts its
#: query threads from Python (about a millisecond), more than a small query costs.
PARALLEL_QUERY_POINTS = 1 << 15


def query_workers(points: int) -> int:
    """``workers`` for a k-d tree query of ``points`` points (-1: all cores)."""
    return -1 if points >= PARALLEL_QUERY_POINTS else 1


def region_albedo(id_map: np.ndarray, sample_xy: np.ndarray, sample_ids: np.ndarray,
                  sample_albedo: np.ndarray, nearest: np.ndarray | None = None) -> np.ndarray:
    """Per-pixel albedo estimated from the samples of the pixel's own id.

    A region whose samples all share one albedo (the usual case: one shape
    of one colour) gets it everywhere.  A region whose samples differ (a
    texture, or the paper rule's id collisions between shapes) takes, at
    each pixel, the albedo of the nearest sample of the same id.  Ids that
    no sample carries get 1 (no modulation).

    ``nearest`` (height, width), optional: index of each pixel's nearest
    sample of any id (:meth:`SamplePattern.nearest_image` of the sample
    indices).  Where that sample has the pixel's id it is also the nearest
    of the same id, so only the other pixels need a k-d tree query.

    Examples
    --------
    >>> xy = np.array([[0, 0], [1, 0]])
    >>> region_albedo(np.array([[1, 1, 2]]), xy, np.array([1, 1]), np.array([[0.2], [0.4]]))[0, :, 0]
    array([0.2, 0.4, 1. ])
    """
    sample_albedo = safe_albedo(sample_albedo)
    sample_ids = np.asarray(sample_ids)
    regions, first, inverse = np.unique(sample_ids, return_index=True, return_inverse=True)
    order = np.argsort(inverse, kind="stable")
    bounds = np.searchsorted(inverse[order], np.arange(len(regions) + 1))  # region k: bounds[k:k+2]
    starts = bounds[:-1]
    spread = (np.maximum.reduceat(sample_albedo[order], starts)
              - np.minimum.reduceat(sample_albedo[order], starts)).max(axis=1)
    varies = spread > ALBEDO_EPS
    out = np.empty(id_map.shape + sample_albedo.shape[1:])
    flat_out = out.reshape(-1, sample_albedo.shape[1])
    rest = np.arange(id_map.size)
    if nearest is not None:
        # where the nearest sample carries the pixel's id, it is the answer for a
        # varying region; a constant one takes its first sample's, as below
        candidate = nearest.ravel()
        per_sample = np.where(varies[inverse][:, None], sample_albedo,
                              sample_albedo[first[inverse]])
        np.take(per_sample, candidate, axis=0, out=flat_out)  # then mend the others
        rest = np.flatnonzero(sample_ids[candidate] != id_map.ravel())
    rest_ids = id_map.ravel()[rest]
    flat_out[rest] = region_values(rest_ids, sample_ids, sample_albedo, "first", 1.0)
    width = id_map.shape[1]
    for k in np.flatnonzero(varies):
        pixels = rest[rest_ids == regions[k]]
        if len(pixels) == 0:
            continue
        members = order[bounds[k]:bounds[k + 1]]
        tree = cKDTree(sample_xy[members])
        closest = tree.query(np.stack([pixels % width, pixels // width], axis=1),
                             workers=query_workers(len(pixels)))[1]
        flat_out[pixels] = sample_albedo[members[closest]]
    return out


def albedo_constant_per_id(sample_ids: np.ndarray, albedo: np.ndarray) -> bool:
    """True when every id's samples share one albedo: a spread of at most
    ``ALBEDO_EPS`` per channel, the criterion of :func:`region_albedo`.

    Then interpolating radiance is interpolating irradiance times one
    albedo per id (the interpolants are linear in the values), and the
    division by albedo and the multiplication back can be skipped.

    Examples
    --------
    >>> albedo_constant_per_id(np.array([1, 1, 2]), np.array([[0.5], [0.5], [0.9]]))
    True
    """
    order = np.argsort(sample_ids, kind="stable")
    ids = sample_ids[order]
    starts = run_starts(ids)
    for channel in np.asarray(albedo).T:  # channel by channel: often column-major
        values = channel[order]
        spread = np.maximum.reduceat(values, starts) - np.minimum.reduceat(values, starts)
        if spread.max() > ALBEDO_EPS:
            return False
    return True


def compose(irradiance: np.ndarray, albedo: np.ndarray, known_mask: np.ndarray,
            known_radiance: np.ndarray) -> np.ndarray:
    """Colour image: ``irradiance * albedo``, with traced pixels kept exactly.

    Parameters
    ----------
    irradiance, albedo : ndarray, shape (height, width, channels)
    known_mask : ndarray of bool, shape (height, width)
    known_radiance : ndarray, shape (known_mask.sum(), channels)
        Traced radiance in the row-major order of ``known_mask``.
    """
    image = np.asarray(irradiance, dtype=np.float64) * albedo
    image[known_mask] = known_radiance
    return image
