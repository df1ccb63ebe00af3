"""The albedo of the id pass: every pixel, in two steps (Mitsuba-specific).

The id pass (mode ``idpass``) gives every pixel of the image its albedo,
without the nested integrator.  Inside a surface of one colour the albedo
is the same at every sample, so one sample per pixel gives it exactly; only
where it varies within a pixel's footprint (an edge between surfaces, a
texture, a rough BSDF whose sampled weight varies) do the samples average
to something else.  So every pixel is traced with one sample first, and the
pixels near a change (of the surface seen at the pixels' centres, or of
those single-sample albedos) again with :data:`ALBEDO_SAMPLES`, the count of
a one-step pass, through the film's filter.  Where every shape's albedo is
one colour (:func:`~.scene_query.shape_albedos`) the first step is not
traced: a sample gives the albedo of the shape, and side, it sees.  The
first step develops its samples with a box filter (each in its own pixel):
where the albedo is one, a filter changes nothing, and where it is not, the
second step replaces it.
Through a box filter the second step sums each pixel's own samples; through
a wider one it splats them over an image-sized block, as ``mi.render`` does.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from .develop import _Developed, _every_pixel
from .pixel_filter import filter_table
from .replay import active as replay_active
from .replay import padded_size
from .scene_query import set_sample_count

#: Samples per pixel of an albedo-only pass (the id pass), where the albedo
#: varies.  A pixel traced with the nested integrator takes its albedo from
#: all of its samples, the same ones as its radiance, so that the two see the
#: same footprint.
ALBEDO_SAMPLES = 16

#: Albedos (per channel, in [0, 1]) that differ by less are one surface's:
#: the weights of one diffuse BSDF are equal, their filtered means round apart.
ALBEDO_TOLERANCE = 1e-4

#: Added to the seed of the second step, so that its samples are not the
#: first step's (the golden ratio's 32-bit constant).
SECOND_SEED = 0x9E3779B9


def albedo_pass(develop, scene, sensor, sampler, pixel_xy: np.ndarray, seed: int,
                replay: bool, box: bool, surface: tuple | None,
                centre: np.ndarray | None = None) -> _Developed:
    """The albedo of ``pixel_xy``, traced without the nested integrator.

    ``develop`` is :func:`~.develop._develop_jit` or its scalar twin;
    ``sampler`` is at the trace's spp, of which at most
    :data:`ALBEDO_SAMPLES` are taken (rounded up as the sampler takes
    them).  ``surface`` is what the pixels' centres see, (shape index,
    mirror path) per pixel, or None; with it, and when ``pixel_xy`` is
    every pixel of the image, the pass takes two steps
    (see the module), else one; with it the samples' normal is not developed
    (zero: the trace takes the centres').  ``centre`` (n, 3), where every
    surface's albedo is one colour (:func:`~.scene_query.shape_albedos`), is
    the albedo of the surface each centre sees: the first step's, untraced.
    """
    # the count as the sampler takes it, as the trace's own spp: orthogonal
    # rounds 16 up to 25 and refuses a launch of 16 samples a pixel, stratified
    # rounds 8 up to 9 and leaves a stratum unsampled in a launch of 8
    count = set_sample_count(sampler.clone(), min(sampler.sample_count(), ALBEDO_SAMPLES))
    width, height = (int(v) for v in sensor.film().crop_size())
    # with the centres' surface the trace takes their normal: the samples' is not developed
    normals = surface is None
    if surface is None or count == 1 or not _every_pixel(pixel_xy, width, height):
        set_sample_count(sampler, count)
        return develop(scene, sensor, None, sampler, pixel_xy, count, seed, True, replay, box,
                       normals=normals)
    if centre is not None:  # what one sample would give, where it sees the centre's surface
        n = len(pixel_xy)
        first = _Developed(np.zeros((n, 3)), np.zeros(n), np.zeros((n, 3)),
                           np.array(centre, dtype=np.float64), np.zeros((n, 3)))
    else:
        one = set_sample_count(sampler, 1)  # (at least 4 for orthogonal and ldsampler)
        # each sample in its own pixel: where the albedo is one, the filter changes nothing
        first = develop(scene, sensor, None, sampler, pixel_xy, one, seed, True, replay, True,
                        normals=False)
    reach = _reach(None if box else sensor.film().rfilter())
    # (the centres' albedo follows their surface: it tells no change of its own)
    again = varied_pixels(pixel_xy, width, height, None if centre is not None else first.albedo,
                          surface, reach)
    if again.any():
        set_sample_count(sampler, count)
        second = _second_step(develop, scene, sensor, sampler, pixel_xy[again], reach, count,
                              (seed + SECOND_SEED) & 0xFFFFFFFF, replay, box)
        first.albedo[again] = second.albedo  # (no normals: the trace takes the centres')
    return first


def _reach(rfilter) -> int:
    """Pixels beyond its own that a pixel's samples reach through ``rfilter``
    (None: the box filter, none)."""
    if rfilter is None:
        return 0
    return max(0, math.ceil(float(filter_table(rfilter).radius) - 0.5))


def varied_pixels(pixel_xy: np.ndarray, width: int, height: int, albedo: np.ndarray | None,
                  surface: tuple, reach: int) -> np.ndarray:
    """(n,) bool: pixels near which the surface seen or the albedo changes.

    Two neighbouring pixels differ where one of the ``surface`` keys (arrays
    per pixel) differs, or an ``albedo`` channel (if given) by more than
    :data:`ALBEDO_TOLERANCE`; both, and every pixel within ``reach + 1`` of
    either, are marked: their samples (which reach ``reach`` pixels away)
    may see more than one albedo.

    Examples
    --------
    >>> xy = np.stack(np.meshgrid(np.arange(6), np.arange(1)), -1).reshape(-1, 2)
    >>> shape = np.array([1, 1, 1, 2, 2, 2])
    >>> varied_pixels(xy, 6, 1, np.full((6, 3), 0.5), (shape,), 0).astype(int).tolist()
    [0, 1, 1, 1, 1, 0]
    """
    x, y = pixel_xy[:, 0], pixel_xy[:, 1]
    # the id pass's pixels come in the image's own order: its arrays are images already
    in_order = len(pixel_xy) == width * height and bool(
        (y * width + x == np.arange(len(pixel_xy))).all())
    changed = np.zeros((height, width), dtype=bool)

    def mark(across: np.ndarray, down: np.ndarray) -> None:
        changed[:, 1:] |= across
        changed[:, :-1] |= across
        changed[1:] |= down
        changed[:-1] |= down

    def image_of(values: np.ndarray) -> np.ndarray:
        if in_order:
            return values.reshape((height, width) + values.shape[1:])
        image = np.zeros((height, width) + values.shape[1:], dtype=values.dtype)
        image[y, x] = values
        return image

    for key in surface:
        image = image_of(np.asarray(key))
        mark(image[:, 1:] != image[:, :-1], image[1:] != image[:-1])
    if albedo is not None:
        image = image_of(np.asarray(albedo))
        for channel in range(image.shape[-1]):
            c = image[..., channel]
            mark(np.abs(c[:, 1:] - c[:, :-1]) > ALBEDO_TOLERANCE,
                 np.abs(c[1:] - c[:-1]) > ALBEDO_TOLERANCE)
    marked = ndimage.maximum_filter(changed, size=2 * reach + 3, mode="constant")
    return marked.ravel() if in_order else marked[y, x]


#: Where the padding of a set of pixels is traced: far enough outside the
#: image that no filter splats a sample of it into a pixel.
OUTSIDE = -64


def _second_step(develop, scene, sensor, sampler, pixel_xy, reach, count, seed, replay,
                 box) -> _Developed:
    """``develop`` of ``pixel_xy`` (a set whose size changes from render to
    render) at ``count`` spp, as a one-step pass develops them.

    Where no sample leaves its pixel (``reach`` 0: a box filter) each pixel
    is its own samples' sum, as a sparse trace's; else the pixels are
    splatted, as ``mi.render`` does, from every pixel whose samples reach
    them, through an image-sized block.  With ``replay`` the traced set is
    padded to :func:`~.replay.padded_size` with pixels outside the image,
    and replayed.
    """
    sources = None
    if reach > 0:  # every pixel whose samples reach them
        width, height = (int(v) for v in sensor.film().crop_size())
        mask = np.zeros((height, width), dtype=bool)
        mask[pixel_xy[:, 1], pixel_xy[:, 0]] = True
        sources = np.argwhere(ndimage.maximum_filter(mask, size=2 * reach + 1,
                                                     mode="constant"))[:, ::-1]
    traced = pixel_xy if sources is None else sources
    if replay and replay_active():
        pad = np.full((padded_size(len(traced)) - len(traced), 2), OUTSIDE, dtype=np.int64)
        traced = np.concatenate([traced, pad])
    if sources is None:
        return _first_rows(develop(scene, sensor, None, sampler, traced, count, seed, True,
                                   replay, box, normals=False), len(pixel_xy))
    return develop(scene, sensor, None, sampler, pixel_xy, count, seed, True, replay, box,
                   traced)


def _first_rows(developed: _Developed, n: int) -> _Developed:
    """``developed`` of its first ``n`` pixels (the padding dropped)."""
    return _Developed(*(None if v is None else v[:n] for v in (
        developed.radiance, developed.alpha, developed.variance, developed.albedo,
        developed.normal, developed.odd)))
