"""Stage 2b: turning the trace's AOVs into region ids.

The trace reports, per traced pixel, ``shape_index`` (0 = background, else
1 + the shape's rank by ``id``) and ``visible_lights``, a bit
mask over the scene's point, spot and directional lights (bit ``k`` set when light ``k``
is unoccluded from the hit point).  Two rules turn them into integer ids:

``paper``
    The report's rule: id = shape + 0.5 per blocked light, stored here in
    half units as ``2 * shape_index + blocked`` so that it stays an integer
    and sorts the same way.  It collides: shape k with two blocked lights
    equals shape k + 1 with none.
``exact``
    ``(shape_index << 32) | visible_lights``: one id per (shape, set of
    visible lights) pair, never colliding.  The trace passes its
    ``path_id`` as ``shape_index`` here: the shape, and the shapes met
    through mirrors, the shape inside an instance's group and the side of
    the surface seen (:meth:`~mitsuba_mrt.types.SparseTrace.ids`).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..errors import MRTError
from .metrics import edge_mask

ID_RULES = ("paper", "exact")


def blocked_count(visible_lights: np.ndarray, num_lights: int) -> np.ndarray:
    """Number of the ``num_lights`` lights whose bit is not set."""
    mask = np.uint64((1 << num_lights) - 1)
    visible = np.asarray(visible_lights, dtype=np.uint64) & mask
    return num_lights - np.bitwise_count(visible).astype(np.int64)


def encode_ids(shape_index: np.ndarray, visible_lights: np.ndarray,
               num_lights: int, rule: str = "paper") -> np.ndarray:
    """Integer region ids from the trace's AOVs; background is always 0.

    Parameters
    ----------
    shape_index : ndarray of int
        0 for background, else the 1-based shape number.
    visible_lights : ndarray of int
        Bit mask of the visible lights (bit k = light k).
    num_lights : int
        Number of lights that the mask covers (at most 32).
    rule : {'paper', 'exact'}

    Examples
    --------
    >>> encode_ids(np.array([1, 2, 0]), np.array([0b00, 0b11, 0]), 2, "paper")
    array([4, 4, 0])
    """
    if rule not in ID_RULES:
        raise MRTError(f"id rule must be one of {', '.join(ID_RULES)}, got {rule!r}")
    if not 0 <= num_lights <= 32:
        raise MRTError(f"ids track at most 32 lights, got {num_lights}")
    shape_index = np.asarray(shape_index, dtype=np.int64)
    background = shape_index == 0
    if rule == "paper":
        ids = 2 * shape_index + blocked_count(visible_lights, num_lights)
    else:
        mask = np.asarray(visible_lights, dtype=np.int64) & ((1 << num_lights) - 1)
        ids = (shape_index << 32) | mask
    return np.where(background, 0, ids)


#: Set in the ids of a surface's pixels near a light (:func:`light_halo`):
#: above every id :func:`encode_ids` makes (shapes below 2^30).
HALO_BIT = 1 << 62


def light_halo(emitter: np.ndarray, id_map: np.ndarray, reach: int,
               background: int = 0) -> np.ndarray:
    """(height, width) bool: the pixels of a surface (not a light, not the
    ``background`` id) within ``reach`` pixels (Chebyshev) of a pixel that sees a light.

    A pixel filter wider than a pixel mixes each pixel with the light of its
    neighbours: beside a light that is many times brighter than the surface
    around it, the surface's pixels within the filter's reach are bright
    with the light's, and the ones beyond are not.  Interpolated together,
    the halo's values would spread over the surface; set apart
    (``ids | HALO_BIT``), each part is interpolated from its own samples.

    Parameters
    ----------
    emitter : ndarray of bool, shape (height, width)
        Pixels whose centre sees a shape that emits light.
    id_map : ndarray of int, shape (height, width)
    reach : int
        How far a pixel's samples reach (0: the box filter, no halo).
    background : int
        The background's id in ``id_map`` (-1: none), never in a halo.

    Examples
    --------
    >>> light = np.zeros((5, 6), bool); light[0, 1:4] = True
    >>> ids = np.where(light, 9, 3); ids[:, 5] = 0
    >>> light_halo(light, ids, 1).astype(int)
    array([[1, 0, 0, 0, 1, 0],
           [1, 1, 1, 1, 1, 0],
           [0, 0, 0, 0, 0, 0],
           [0, 0, 0, 0, 0, 0],
           [0, 0, 0, 0, 0, 0]])
    """
    emitter = np.asarray(emitter, dtype=bool)
    if reach <= 0 or not emitter.any():
        return np.zeros(emitter.shape, dtype=bool)
    near = ndimage.maximum_filter(emitter, size=2 * int(reach) + 1, mode="constant")
    return near & ~emitter & (np.asarray(id_map) != background)


def id_to_paper_float(ids: np.ndarray) -> np.ndarray:
    """The report's float id (shape + 0.5 per blocked light) of a paper-rule id."""
    return np.asarray(ids, dtype=np.float64) / 2.0


def rank_ids(ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct ids, sorted, and each id's rank among them.

    Ranks keep the ids' order and equalities in a small integer type
    (int16 below 32,768 distinct ids, else int32; -1 is free as a
    sentinel), so that masks, copies and comparisons over whole images of
    ids move a quarter of the bytes of int64 ids; ``labels[ranks]`` gives
    the ids back.

    Examples
    --------
    >>> labels, ranks = rank_ids(np.array([7, 0, 1 << 32, 7]))
    >>> labels.tolist(), ranks.tolist(), ranks.dtype.name
    ([0, 7, 4294967296], [1, 0, 2, 1], 'int16')
    """
    ids = np.asarray(ids)
    ordered = np.sort(ids, axis=None)
    labels = ordered[run_starts(ordered)]
    dtype = np.int16 if len(labels) < 1 << 15 else np.int32
    return labels, np.searchsorted(labels, ids).astype(dtype)


def run_starts(sorted_values: np.ndarray) -> np.ndarray:
    """Index of the first element of each run of equal values in a sorted 1-D array.

    Examples
    --------
    >>> run_starts(np.array([2, 2, 5, 7, 7, 7])).tolist()
    [0, 2, 3]
    """
    values = np.asarray(sorted_values)
    if values.size == 0:
        return np.zeros(0, dtype=np.intp)
    return np.flatnonzero(np.concatenate(([True], values[1:] != values[:-1])))


def edge_share(id_map: np.ndarray) -> float:
    """The share of an image's pixels that have a 4-neighbour of another id.

    Examples
    --------
    >>> ids = np.zeros((4, 4), dtype=int); ids[:, 2:] = 1
    >>> edge_share(ids)
    0.5
    >>> edge_share(np.zeros((3, 3), dtype=int))
    0.0
    >>> edge_share(np.array([[1, 1, 2], [1, 1, 2], [1, 1, 2]]))
    0.6666666666666666
    """
    ids = np.asarray(id_map)
    return float(edge_mask(ids).mean()) if ids.size else 0.0
