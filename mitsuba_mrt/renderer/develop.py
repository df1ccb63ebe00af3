"""Tracing and developing the samples of traced pixels (Mitsuba-specific).

A traced pixel is what ``mi.render`` gives at that pixel: its samples
follow the film's reconstruction filter (:mod:`.pixel_filter`) and are
developed as Mitsuba's own image block does, spectra converted to the RGB
that ``mi.render`` writes, alpha included.  In a JIT variant (LLVM, CUDA)
every sample of every traced pixel is one lane of a single Dr.Jit
wavefront; the scalar variant loops over the samples in Python.

Each sample also gives the albedo of its first hit, the directional albedo
of the BSDF for the view direction (the mean weight of a BSDF sample),
averaged like the radiance: what multiplies the incoming light, bounded by
one; and the shading normal there.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from .lanes import is_jit, logical_not
from .pixel_filter import GUIDE_BINS, filter_table
from .replay import Replay
from .scene_query import has_delta_lobes, sampler_bakes_spp

#: Specular (mirror) bounces followed: by a sample's albedo (:func:`_albedo_along`)
#: and by the id trace (:mod:`.ids`).
MIRROR_DEPTH = 4

#: A pixel's sample variance below this share of its samples' mean square is
#: taken as 0: the sums are float32, so their difference rounds to ~1e-7 of it.
VARIANCE_FLOOR = 1e-6

#: Channels of the image block the samples are developed in: weighted RGB,
#: alpha, the weight, RGB squared (for the variance), albedo and its weight,
#: the count of samples whose radiance was NaN or Inf, and the shading normal
#: (weighted as the albedo); with ``halves``, also the weighted RGB of the
#: odd-numbered samples and their weight (:data:`_HALF_CHANNELS` more); with
#: the albedo of a few samples, its square (:data:`_SQUARE_CHANNELS`, after
#: the others).
_CHANNELS, _HALF_CHANNELS, _SQUARE_CHANNELS = 16, 4, 3

#: Samples per pixel whose albedo is traced where every shape's albedo is one
#: colour (:func:`.scene_query.albedo_per_shape`): where they all hit one
#: surface, or none, their albedo is the pixel's; where they disagree, the
#: caller traces the pixel's albedo again (``albedo_varies``).  A sample's
#: albedo costs a ray from the camera and a BSDF sample, beside the radiance's.
#: With 4 a surface covering a tenth of a pixel went unseen in two pixels of
#: three; 16 miss it in one of five, and cost no more.
ALBEDO_FIRST_SAMPLES = 16


def _channels(halves: bool) -> int:
    """Channels of a block developed with or without ``halves``."""
    return _CHANNELS + _HALF_CHANNELS if halves else _CHANNELS


@dataclass
class _Developed:
    """Per traced pixel, what its samples gave (numpy)."""

    radiance: np.ndarray  # (n, 3) the developed RGB
    alpha: np.ndarray     # (n,)
    variance: np.ndarray  # (n, 3) of a single sample's RGB about the pixel's mean
    albedo: np.ndarray    # (n, 3)
    normal: np.ndarray | None = None  # (n, 3) the samples' mean shading normal
    odd: np.ndarray | None = None     # (n, 3) the mean RGB of the odd-numbered samples
    # (n,) where the albedo came from a few samples: whether they disagreed
    albedo_varies: np.ndarray | None = None


def _camera_ray(sensor, sampler, position, spp, centre: bool = False):
    """A camera ray through ``position`` (crop-relative pixel coordinates),
    its differentials scaled for ``spp`` (an int, or a Dr.Jit value).

    ``centre`` rays use no random numbers: no aperture, time or wavelength
    sample.
    """
    film_size = mi.ScalarVector2f(sensor.film().crop_size())
    aperture = sampler.next_2d() if (sensor.needs_aperture_sample() and not centre) \
        else mi.Point2f(0.5, 0.5)
    ray_time = sensor.shutter_open()
    if sensor.shutter_open_time() > 0 and not centre:
        ray_time += sampler.next_1d() * sensor.shutter_open_time()
    wavelength = sampler.next_1d() if (mi.is_spectral and not centre) else 0.0
    ray, weight = sensor.sample_ray_differential(ray_time, wavelength, position / film_size,
                                                 aperture)
    ray.scale_differential(dr.rsqrt(mi.Float(spp)))
    return ray, weight


def nested_sample(integrator, scene, sampler, ray, active, medium=None):
    """``(value, valid, aovs)`` of one sample of the nested ``integrator`` along ``ray``,
    which starts in ``medium`` (the camera's, as ``mi.render`` passes it).

    Mitsuba's C++ integrators (``path``, ``volpath``, ...) and the MRT's own
    take ``sample(scene, sampler, ray, medium, active)``; its differentiable
    Python integrators (``prb``, ``prbvolpath``, ``direct_projective``, ...,
    subclasses of ``mi.CppADIntegrator``) take an AD mode and their
    derivatives' state, and give their primal estimate for
    ``dr.ADMode.Primal``, as their own ``render`` asks for it (no medium:
    their paths start outside any, in their own renders too).
    """
    if isinstance(integrator, mi.CppADIntegrator):
        value, valid, aovs, _ = integrator.sample(
            mode=dr.ADMode.Primal, scene=scene, sampler=sampler, ray=ray, depth=mi.UInt32(0),
            δL=None, δaovs=None, state_in=None, active=mi.Bool(active))
        return value, valid, aovs
    return integrator.sample(scene, sampler, ray, medium, active)


def _rgb(value, wavelengths, active=True):
    """A sample's value as the RGB that ``mi.render`` develops (spectra converted)."""
    if mi.is_polarized:
        value = mi.unpolarized_spectrum(value)
    if mi.is_spectral:
        return mi.spectrum_to_srgb(value, wavelengths, active)
    if mi.is_monochromatic:  # (grey, as Mitsuba's own integrators develop it)
        return mi.Color3f(value[0])
    return mi.Color3f(value)


def _albedo_along(scene, sampler, ray, active, bounces: int = MIRROR_DEPTH):
    """What multiplies the light arriving at the first hit: its BSDF's albedo
    for the view direction, one BSDF sample's weight, clamped to [0, 1] (RGB);
    with whether the camera ray hit and the shading normal at its hit.

    Through mirrors and glass (delta BSDFs) the path is followed, up to
    ``bounces`` (0 in a scene without delta lobes), and the albedo is that of the surface seen
    times the specular throughput; 0 on a miss.  The mean over a pixel's
    samples estimates the pixel's albedo the way its radiance is estimated.
    The bounces after the first are one symbolic loop (:func:`drjit.while_loop`):
    traced once, and a wavefront's lanes leave it at their first rough surface.
    """
    jit = is_jit()
    ray = mi.Ray3f(ray)
    si, hit = _intersect(scene, ray, mi.Bool(active) if jit else bool(active), coherent=True)
    normal = dr.select(hit, si.sh_frame.n, 0.0) if jit else (
        si.sh_frame.n if hit else mi.Vector3f(0.0))
    albedo, throughput, ray, active = _scatter(si, ray, hit, sampler, mi.Color3f(1.0),
                                               mi.Color3f(0.0), bounces == 0)

    def more(depth, ray, throughput, albedo, active, sampler):
        return active

    def bounce(depth, ray, throughput, albedo, active, sampler):
        si, valid = _intersect(scene, ray, active, coherent=False)
        albedo, throughput, ray, active = _scatter(si, ray, valid, sampler, throughput, albedo,
                                                   depth == bounces)
        return depth + 1, ray, throughput, albedo, active, sampler

    if bounces > 0:
        albedo = dr.while_loop((mi.UInt32(1) if jit else 1, ray, throughput, albedo, active,
                                sampler), more, bounce, label="mrt_albedo_along")[3]
    return albedo, hit, normal


def _intersect(scene, ray, active, coherent: bool):
    """(the hit of ``ray`` for lanes ``active``, whether it is a surface)."""
    si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.All, coherent=coherent, active=active)
    return si, (active & si.is_valid() if is_jit() else bool(active and si.is_valid()))


def _scatter(si, ray, valid, sampler, throughput, albedo, last):
    """One BSDF sample at ``si`` (lanes ``valid``): (the albedo, set where the
    path ends here: a non-delta lobe, or a delta one at the ``last`` bounce;
    the throughput times the sample's weight; the next ray; whether the path
    goes on)."""
    if not (is_jit() or valid):
        return albedo, throughput, ray, False
    bsdf = si.bsdf(ray)
    bs, weight = bsdf.sample(mi.BSDFContext(), si, sampler.next_1d(valid),
                             sampler.next_2d(valid), valid)
    weight = dr.clip(_rgb(weight, si.wavelengths, valid), 0.0, 1.0)
    delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
    done = valid & (bs.pdf > 0.0) & (logical_not(delta) | last)
    albedo = dr.select(done, throughput * weight, albedo)
    return (albedo, throughput * weight, si.spawn_ray(si.to_world(bs.wo)),
            valid & (bs.pdf > 0.0) & logical_not(done))


def _read_sums(sums, radiance: bool = True) -> _Developed:
    """The developed values of the traced pixels from their filter-weighted
    sums: a sequence of channels, each ``(n,)`` (whole contiguous rows, not
    strided columns, for the arithmetic; only the channels used are read);
    without ``radiance`` (an albedo-only trace) its fields are zero."""
    def reciprocal(weight):  # 0 where nothing was accumulated
        out = np.zeros_like(weight)
        np.divide(1.0, weight, out=out, where=weight != 0.0)
        return out

    def rows(first, stop):  # channels first .. stop - 1 as a (k, n) float64 array
        return np.stack([np.asarray(c, dtype=np.float64) for c in sums[first:stop]])

    def pixels(channels):  # (k, n) -> (n, k), C-contiguous as the callers expect
        return np.ascontiguousarray(channels.T)

    n = len(sums[0])
    per_albedo_weight = reciprocal(np.maximum(np.asarray(sums[11], dtype=np.float64), 0.0))
    albedo = pixels(np.clip(rows(8, 11) * per_albedo_weight, 0.0, 1.0))
    normal = pixels(np.clip(rows(13, 16) * per_albedo_weight, -1.0, 1.0))
    if not radiance:
        return _Developed(np.zeros((n, 3)), np.zeros(n), np.zeros((n, 3)), albedo, normal)
    per_weight = reciprocal(np.asarray(sums[4], dtype=np.float64))
    rgb = rows(0, 3) * per_weight
    odd = None
    if len(sums) > _CHANNELS:  # the odd-numbered samples' own mean
        odd = pixels(rows(_CHANNELS, _CHANNELS + 3)
                     * reciprocal(np.asarray(sums[_CHANNELS + 3], dtype=np.float64)))
    second = rows(5, 8) * per_weight
    # a sample's NaN or Inf: reported by the caller's check, as a full render's
    rgb[:, np.asarray(sums[12]) > 0.0] = np.nan
    return _Developed(pixels(rgb), np.asarray(sums[3], dtype=np.float64) * per_weight,
                      pixels(sample_variance(second, rgb)), albedo, normal, odd)


def _every_pixel(pixel_xy: np.ndarray, width: int, height: int) -> bool:
    """Whether ``pixel_xy`` is every pixel of the image, each once."""
    count = width * height
    if len(pixel_xy) != count:
        return False
    x, y = pixel_xy[:, 0], pixel_xy[:, 1]
    if x.min() < 0 or y.min() < 0 or x.max() >= width or y.max() >= height:
        return False
    # a counting pass, not a sort: the id pass asks this of every pixel
    return bool((np.bincount(y * width + x, minlength=count) == 1).all())


#: Bytes to which the arrays given to a recorded trace are aligned (a cache line,
#: and the widest SIMD register).
ALIGNMENT = 64


def _aligned(values: np.ndarray, dtype=np.float32):
    """``values`` as a Dr.Jit ``Float`` (``UInt32`` for ``dtype`` uint32) over
    a copy aligned to :data:`ALIGNMENT`.

    Dr.Jit maps a NumPy array's memory instead of copying it, and a frozen
    call (:mod:`.replay`) is recorded anew whenever an input's memory turns
    from aligned to unaligned or back: NumPy's buffers are aligned or not by
    chance, so the same trace was recorded again on some renders.
    """
    values = np.asarray(values, dtype=dtype).ravel()
    slack = ALIGNMENT // values.itemsize
    buffer = np.empty(len(values) + slack, dtype=dtype)
    start = (-buffer.ctypes.data % ALIGNMENT) // values.itemsize
    out = buffer[start:start + len(values)]
    out[...] = values
    return (mi.UInt32 if dtype == np.uint32 else mi.Float)(out)


def _develop_jit(scene, sensor, integrator, sampler, pixel_xy, spp, seed, albedo, replay,
                 box=False, sources=None, halves=False, normals=True, albedo_samples=0,
                 variance=True):
    """Trace ``spp`` samples of every pixel in one wavefront and develop them.

    Every pixel of the image: as ``mi.render`` does (uniform over each pixel,
    splatted with the filter).  Some pixels: each from its own samples, placed
    with the filter's distribution (:mod:`.pixel_filter`); or, given
    ``sources``, the pixels whose samples are splatted as ``mi.render``'s
    (every pixel within the filter's reach of ``pixel_xy``, for their values
    to be ``mi.render``'s kind; pixels outside the image add nothing).
    ``sampler`` is :func:`_develop_scalar`'s; the kernels clone the sensor's own.
    With ``halves`` the odd-numbered samples of each pixel are also developed
    on their own (``odd``).  Only the channels that are read are added up:
    without ``normals`` (a caller that takes the normal of each pixel's
    centre instead) no normal, and ``normal`` is zero.  With
    ``albedo_samples`` (not where the samples are splatted or a filter's
    negative lobe weighs them -1), only each pixel's first that many samples
    trace the albedo, and ``albedo_varies`` says whether they disagreed (or
    some missed every surface).  Without ``variance`` (where no stage reads
    it) each pixel's variance is not worked out from its sums, and is zero.
    """
    film = sensor.film()
    width, height = (int(v) for v in film.crop_size())
    table = filter_table(box_filter() if box else film.rfilter())
    every = sources is not None or _every_pixel(pixel_xy, width, height)
    # every pixel through a box filter: each sample stays in its pixel, whose
    # sums are its own lanes', as for some pixels (no image block)
    splat = every and (sources is not None or not box)
    traced = pixel_xy if sources is None else sources
    n = len(traced)
    few = (int(albedo_samples) if albedo and integrator is not None and not splat
           and not table.negative and albedo_samples > 0 else 0)
    read = _read_channels(integrator is not None, bool(albedo), bool(normals), bool(halves),
                          bool(few))
    first = table.guide[0]
    layout = _layout(scene, sensor, integrator, n, spp, albedo, every, splat, table, box,
                     halves, normals, few)
    sums = _DEVELOP(scene, sensor, integrator, _aligned(traced[:, 0]),
                    _aligned(traced[:, 1]), _aligned(table.cdf),
                    _aligned(first, np.uint32),
                    dr.opaque(mi.UInt32, seed & 0xFFFFFFFF), dr.opaque(mi.UInt32, spp),
                    _lanes(n * spp), layout,
                    objects=(scene, sensor, integrator), record=replay)
    if splat:  # the block holds the channels read, in order; the others are zero
        block = sums.numpy().reshape(width * height, len(read))
        index = pixel_xy[:, 1] * width + pixel_xy[:, 0]
        in_order = len(index) == width * height and bool((index == np.arange(len(index))).all())
        rows = np.ascontiguousarray((block if in_order else block[index]).T)
        sums = [np.zeros(len(pixel_xy), dtype=rows.dtype) for _ in range(_channels(halves))]
        for row, k in zip(rows, read):
            sums[k] = row
        return _read_sums(sums, integrator is not None)
    return _unpacked(sums, n, integrator is not None, bool(albedo), bool(halves),
                     bool(albedo and normals), bool(few), variance)


def _lanes(count: int):
    """The samples' lanes for :func:`_develop_kernel`: ``count`` True values,
    an input whose width a replay of a recording takes as the samples'."""
    return dr.arange(mi.UInt32, count) < dr.opaque(mi.UInt32, count)


def _layout(scene, sensor, integrator, n: int, spp: int, albedo, every: bool, splat: bool,
            table, box: bool, halves, normals, few: int) -> tuple:
    """What :func:`_develop_kernel` bakes in (its ``layout``), so that a
    recording is replayed only where it holds: the spp where the sampler
    bakes it into its arithmetic (:func:`.scene_query.sampler_bakes_spp`),
    else :func:`spp_class`'s, and a recording replays at every spp of its class."""
    film = sensor.film()
    steps = None if table.uniform else table.guide[1]
    baked = spp_class(spp, sampler_bakes_spp(sensor.sampler()))
    return (n, baked, integrator is not None, bool(albedo), every, splat,
            *(int(v) for v in film.crop_size()), tuple(int(v) for v in film.crop_offset()),
            bool(film.sample_border()), float(table.radius), len(table.pdf), steps, bool(box),
            MIRROR_DEPTH if albedo and has_delta_lobes(scene) else 0, bool(halves),
            bool(albedo and normals), few)


def spp_class(spp: int, bakes: bool) -> int:
    """The spp a recording of :func:`_develop_jit` is made for, that replays
    for ``spp``: ``spp`` itself where the sampler bakes it (``bakes``), else
    1 for 1 and 2 for every larger count (a recording made at 1 spp, whose
    samples are as many as its pixels, did not replay at more: Dr.Jit
    recorded again).

    Examples
    --------
    >>> [spp_class(spp, False) for spp in (1, 2, 7)], spp_class(7, True)
    ([1, 2, 2], 7)
    """
    return int(spp) if bakes else min(int(spp), 2)


def every_pixel_recorded(scene, sensor, integrator, spp: int, albedo: bool,
                         halves: bool) -> bool:
    """Whether :func:`_develop_jit` has a recording to replay for every pixel
    at ``spp`` through a box filter (the albedo and normals where
    ``albedo``, the odd samples apart where ``halves``): a trace of that
    layout ran before in this process, so its kernels exist."""
    width, height = (int(v) for v in sensor.film().crop_size())
    objects = (scene, sensor, integrator)
    # (a layout's first values: its pixel count and spp; the rest is worked
    # out, its filter's table made, only where a recording has those)
    baked = spp_class(spp, sampler_bakes_spp(sensor.sampler()))
    if all(layout[:2] != (width * height, baked) for layout in _DEVELOP.layouts(objects)):
        return False
    layout = _layout(scene, sensor, integrator, width * height, spp, albedo, True, False,
                     filter_table(box_filter()), True, halves, True, 0)
    return _DEVELOP.recorded(objects, layout)


def any_recorded(scene, sensor, integrator) -> bool:
    """Whether :func:`_develop_jit` recorded a trace of these objects in this
    process (of any layout): their first uses are paid, and a recording of
    another layout costs its tracing alone."""
    return bool(_DEVELOP.layouts((scene, sensor, integrator)))


def filter_cell(u, cdf, first, steps: int, cells: int):
    """The cell of the tabulated filter distribution that uniform numbers ``u``
    (a Dr.Jit ``Float`` in [0, 1)) fall in: the first ``k`` with
    ``cdf[k + 1] > u`` (the last cell where there is none), as a bisection
    of the whole table finds it, bisected within the ``steps + 1`` cells that
    the guide table ``first`` leaves (:meth:`.pixel_filter.FilterTable.guide`).
    """
    k = dr.gather(mi.UInt32, first, dr.minimum(mi.UInt32(u * GUIDE_BINS), GUIDE_BINS - 1))
    candidates = steps + 1
    while candidates > 1:  # the answer lies in [k, k + candidates - 1]
        half = candidates // 2
        k = dr.select(dr.gather(mi.Float, cdf, dr.minimum(k + half, cells)) <= u, k + half, k)
        candidates -= half
    return dr.minimum(k, cells - 1)


def filter_offset(u, cdf, first, steps: int | None, cells: int, radius: float):
    """Offsets from a pixel's centre with density ``|f|`` (the tabulated
    filter's inverse CDF) for uniform numbers ``u`` in [0, 1): within the
    cell :func:`filter_cell` finds, linearly.  ``steps`` None: the table is
    uniform (a box filter), where ``u`` lies ``u * cells`` cells in, exactly
    as the search and the interpolation would find it.
    """
    cell = 2.0 * radius / cells
    if steps is None:
        return -radius + (u * cells) * cell
    k = filter_cell(u, cdf, first, steps, cells)
    lo, hi = dr.gather(mi.Float, cdf, k), dr.gather(mi.Float, cdf, k + 1)
    t = dr.select(hi > lo, (u - lo) / (hi - lo), 0.5)
    return -radius + (mi.Float(k) + t) * cell


def _develop_kernel(scene, sensor, integrator, pixel_x, pixel_y, cdf, first, seed, spp_input,
                    lanes, layout):
    """The kernels of :func:`_develop_jit`: the samples' filter-weighted sums,
    per pixel (a list of channels) or, splatted over every pixel through the
    filter, as an image block's tensor.  Everything they depend on is an
    argument (``layout`` the Python values), so that :func:`drjit.freeze`
    can record and replay them.

    The spp is also an opaque input (``spp_input``), not a literal: a kernel
    compiled for one spp is the kernel of every other (only the sampler's
    own arithmetic may bake it in: ``stratified``, ``multijitter``).  The
    samples' lanes are ``lanes`` (:func:`_lanes`), which every kernel of
    the samples reads: a recording made at one spp replays at another of
    its :func:`spp_class`, its kernels' width taken from theirs.

    The sampler is made here, not passed: a frozen function's inputs are
    also its outputs, and the sampler's state after the samples would cost
    a second kernel over every lane to write back.
    """
    (n, spp, _, albedo, every, splat, width, height, crop_offset, sample_border, radius, cells,
     steps, box, bounces, halves, normals, few) = layout
    film = sensor.film()
    rfilter = box_filter() if box else film.rfilter()
    sampler = sensor.sampler().clone()
    count = dr.width(lanes)  # (as recorded; a replay takes its width from ``lanes``)
    if sampler_bakes_spp(sampler):  # (recorded per spp: ``spp`` is the count)
        sampler.set_sample_count(spp)
        sampler.set_samples_per_wavefront(spp)
    sampler.seed(seed, count)
    owner = dr.arange(mi.UInt32, count) // spp_input  # lanes pixel-major, as Mitsuba's own

    def offset(u):
        return filter_offset(u, cdf, first, steps, cells, radius)

    u = sampler.next_2d()
    pixel = mi.Point2f(dr.gather(mi.Float, pixel_x, owner, lanes),
                       dr.gather(mi.Float, pixel_y, owner, lanes))
    if every:
        position, weight = pixel + u, mi.Float(1.0)
    else:
        d = mi.Point2f(offset(u.x), offset(u.y))
        position = pixel + 0.5 + d
        # f / density is a constant of the filter's sign: the weight is that sign
        weight = dr.sign(rfilter.eval(d.x) * rfilter.eval(d.y))
    active = lanes if sample_border else lanes & (
        (position.x >= 0) & (position.x < width) & (position.y >= 0) & (position.y < height))
    weight = dr.select(active, weight, 0.0)

    ray, ray_weight = _camera_ray(sensor, sampler, position, mi.Float(spp_input))
    zero = mi.Float(0.0)
    rgb, alpha, invalid = mi.Color3f(0.0), zero, zero
    if integrator is not None:
        # (from the medium the camera sits in, as mi.render starts its paths)
        value, valid, _ = nested_sample(integrator, scene, sampler, ray, active,
                                        sensor.get_medium())
        rgb = _rgb(ray_weight * value, ray.wavelengths, active)
        finite = dr.all(dr.isfinite(rgb))
        invalid = dr.select(active & ~finite, 1.0, 0.0)
        rgb = dr.select(active & finite, rgb, 0.0)
        alpha = dr.select(active & valid, 1.0, 0.0)
    a_weight, a_rgb, normal = zero, mi.Color3f(0.0), mi.Vector3f(0.0)
    traces_albedo = active
    if few:  # each pixel's first ``few`` samples (lanes are pixel-major)
        traces_albedo = active & (dr.arange(mi.UInt32, count) - owner * spp_input < few)
    if albedo:  # averaged over the samples that hit a surface
        a_rgb, hit, normal = _albedo_along(scene, sampler, ray, traces_albedo, bounces)
        a_weight = dr.select(traces_albedo & hit, weight, 0.0)
    values = [weight * rgb.x, weight * rgb.y, weight * rgb.z, weight * alpha, weight,
              weight * rgb.x ** 2, weight * rgb.y ** 2, weight * rgb.z ** 2,
              a_weight * a_rgb.x, a_weight * a_rgb.y, a_weight * a_rgb.z, a_weight, invalid,
              a_weight * normal.x, a_weight * normal.y, a_weight * normal.z]
    if halves:  # the odd-numbered samples of each pixel (lanes are pixel-major)
        lane = dr.arange(mi.UInt32, count)
        odd = dr.select(((lane - owner * spp_input) & 1) == 1, weight, 0.0)
        values += [odd * rgb.x, odd * rgb.y, odd * rgb.z, odd]
    if few:  # how far they spread
        values += [a_weight * a_rgb.x ** 2, a_weight * a_rgb.y ** 2, a_weight * a_rgb.z ** 2]
    # The block's scatters, or the sums' below, run in the samples' own kernel:
    # no channel of every sample is written out (0.4 GB at 1000 x 1000, a
    # tenth traced, 64 spp) to be reduced after, which a fresh process pays
    # for in page faults.
    # only the channels read after (no normal's where the caller takes the centre's)
    read = _read_channels(integrator is not None, albedo, normals, halves, bool(few))
    if splat:
        block = _new_block(film, rfilter, len(read))
        block.put(position + mi.ScalarVector2f(crop_offset), [values[k] for k in read], active)
        return block.tensor()
    # The pixel index comes from the opaque spp, and the mode is fixed
    # (``Auto`` switches to per-core copies for small arrays): the kernel is
    # the same at every spp and pixel count.
    sums = [dr.zeros(mi.Float, n) if k in read else None for k in range(len(values))]
    albedo_channels = set(range(8, 12)) | set(range(13, 16))
    if few:
        albedo_channels |= set(range(len(values) - _SQUARE_CHANNELS, len(values)))
    for k in read:  # (the lanes that trace no albedo add none to its channels)
        mask = traces_albedo if few and k in albedo_channels else lanes
        dr.scatter_reduce(dr.ReduceOp.Add, sums[k], values[k], owner, active=mask,
                          mode=dr.ReduceMode.Local)
    few_traced = dr.minimum(mi.Float(few), mi.Float(spp_input)) if few else None
    return _packed(_developed_channels(sums, integrator is not None, albedo, normals, few_traced),
                   n)


def _read_channels(radiance: bool, albedo: bool, normals: bool, halves: bool,
                   squares: bool = False) -> list:
    """The channels of :data:`_CHANNELS` (and the halves', and the albedo's
    squares) that :func:`_developed_channels` reads."""
    read = list(range(0, 8)) + [12] if radiance else []
    read += list(range(8, 12)) if albedo else []
    read += list(range(13, 16)) if albedo and normals else []
    read += list(range(_CHANNELS, _CHANNELS + _HALF_CHANNELS)) if halves else []
    first = _channels(halves)
    return read + (list(range(first, first + _SQUARE_CHANNELS)) if squares else [])


def _developed_channels(sums: list, radiance: bool, albedo: bool, normals: bool = True,
                        few=None) -> list:
    """:func:`_read_sums`'s values as Dr.Jit channels, from the sums'
    (float32, in the kernel), those traced alone: with ``radiance`` the RGB
    (3), alpha and the mean square (3); with ``albedo`` the albedo (3) and,
    with ``normals``, the normal (3); with the halves' sums the odd samples'
    RGB (3); with the albedo of ``few`` samples (a Dr.Jit value: the fewer
    of those asked for and the spp), whether they disagreed (1:
    a spread beyond the float32 sums' rounding, or some of them hit no
    surface while others did)."""
    def per(weight):  # 0 where nothing was accumulated
        return dr.select(weight != 0.0, 1.0 / dr.select(weight != 0.0, weight, 1.0), 0.0)

    out = []
    if radiance:
        per_weight = per(sums[4])
        # a sample's NaN or Inf: reported by the caller's check, as a full render's
        out += [dr.select(sums[12] > 0.0, dr.nan, c * per_weight) for c in sums[0:3]]
        out += [c * per_weight for c in sums[3:4] + sums[5:8]]
    if albedo:
        per_albedo_weight = per(dr.maximum(sums[11], 0.0))
        out += [dr.clip(c * per_albedo_weight, 0.0, 1.0) for c in sums[8:11]]
        if normals:
            out += [dr.clip(c * per_albedo_weight, -1.0, 1.0) for c in sums[13:16]]
    squares = 0 if few is None else _SQUARE_CHANNELS
    if len(sums) - squares > _CHANNELS:  # the odd samples' mean
        per_odd = per(sums[_CHANNELS + 3])
        out += [c * per_odd for c in sums[_CHANNELS:_CHANNELS + 3]]
    if squares:
        per_albedo_weight = per(dr.maximum(sums[11], 0.0))
        square = sum(c * per_albedo_weight for c in sums[-_SQUARE_CHANNELS:])
        spread = square - sum((c * per_albedo_weight) ** 2 for c in sums[8:11])
        some = (sums[11] > 0.0) & (sums[11] < few)
        out.append(dr.select((spread > VARIANCE_FLOOR * square) | some, 1.0, 0.0))
    return out


def _packed(channels: list, n: int):
    """``channels`` (each ``n`` values) as one array, pixel-major: one
    transfer to NumPy, already in the ``(n, k)`` layout the fields take."""
    k = len(channels)
    out = dr.zeros(mi.Float, n * k)
    index = dr.arange(mi.UInt32, n) * k
    for j, channel in enumerate(channels):
        dr.scatter(out, channel, index + j)
    dr.eval(out)
    return out


def _unpacked(packed, n: int, radiance: bool, albedo: bool, halves: bool,
              normals: bool = True, few: bool = False, variance: bool = True) -> _Developed:
    """The :class:`_Developed` of :func:`_packed`'s array of
    :func:`_developed_channels` (float64 fields; zeros where not traced, or
    for the variance, not asked for)."""
    values, at = np.asarray(packed, dtype=np.float64).reshape(n, -1), [0]

    def take(k):  # the next k channels (views of one conversion)
        first = at[0]
        at[0] += k
        return values[:, first:first + k]

    # (zeros of their own, not copies: untraced fields cost no memory until written)
    rgb, alpha, second = (take(3), take(1).reshape(n), take(3)) if radiance else (
        np.zeros((n, 3)), np.zeros(n), None)
    variance = (sample_variance(second, rgb) if second is not None and variance
                else np.zeros((n, 3)))
    guide = (take(3), take(3) if normals else np.zeros((n, 3))) if albedo else (
        np.zeros((n, 3)), np.zeros((n, 3)))
    odd = take(3) if halves else None
    varies = take(1).reshape(n) > 0.0 if few else None
    return _Developed(rgb, alpha, variance, *guide, odd, varies)


def sample_variance(second: np.ndarray, mean: np.ndarray) -> np.ndarray:
    """A single sample's variance from its mean square and mean (float64)."""
    variance = second - mean ** 2
    # below this it is the float32 sums' rounding (a single sample's is all rounding)
    return np.where(variance > VARIANCE_FLOOR * second, variance, 0.0)


def _new_block(film, rfilter, channels: int) -> mi.ImageBlock:
    return mi.ImageBlock(size=film.crop_size(), offset=film.crop_offset(),
                         channel_count=channels, rfilter=rfilter, border=False)


#: The box pixel filter of each variant, made on first use.
_BOX_FILTERS: dict = {}


def box_filter():
    """Mitsuba's ``box`` reconstruction filter (radius half a pixel) in the active variant."""
    rfilter = _BOX_FILTERS.get(mi.variant())
    if rfilter is None:
        rfilter = _BOX_FILTERS[mi.variant()] = mi.load_dict({"type": "box"})
    return rfilter


def _develop_scalar(scene, sensor, integrator, sampler, pixel_xy, spp, seed, albedo,
                    replay=False, box=False, sources=None, halves=False, normals=True,
                    albedo_samples=0, variance=True):
    """The scalar variant's :func:`_develop_jit`: sample by sample in Python
    (the variance and the normals are developed whatever ``variance`` and
    ``normals`` say, and every sample's albedo whatever ``albedo_samples``
    says)."""
    film = sensor.film()
    width, height = (int(v) for v in film.crop_size())
    rfilter = box_filter() if box else film.rfilter()
    table = filter_table(rfilter)
    every = sources is not None or _every_pixel(pixel_xy, width, height)
    traced = pixel_xy if sources is None else sources
    offset = mi.ScalarVector2f(film.crop_offset())
    block = _new_block(film, rfilter, _channels(halves)) if every else None
    sums = np.zeros((len(pixel_xy), _channels(halves)))
    for k, (x, y) in enumerate(traced.tolist()):
        sampler.seed((seed * 0x9E3779B1 + k) & 0xFFFFFFFF)  # a 32-bit seed per pixel
        for s in range(spp):
            u = sampler.next_2d()
            if every:
                px, py, weight = x + u[0], y + u[1], 1.0
            else:
                dx, dy = (float(v) for v in table.sample(np.array([u[0], u[1]])))
                px, py = x + 0.5 + dx, y + 0.5 + dy
                weight = float(np.sign(float(rfilter.eval(dx)) * float(rfilter.eval(dy))))
            if not (film.sample_border() or (0 <= px < width and 0 <= py < height)):
                sampler.advance()
                continue
            ray, ray_weight = _camera_ray(sensor, sampler, mi.Point2f(px, py), spp)
            rgb, alpha, invalid = np.zeros(3), 0.0, 0.0
            if integrator is not None:
                value, valid, _ = nested_sample(integrator, scene, sampler, ray, True,
                                                sensor.get_medium())
                rgb = np.asarray(_rgb(ray_weight * value, ray.wavelengths), dtype=np.float64)
                alpha = 1.0 if valid else 0.0
                if not np.isfinite(rgb).all():
                    rgb, invalid = np.zeros(3), 1.0
            a_rgb, a_weight, normal = np.zeros(3), 0.0, np.zeros(3)
            if albedo:
                a_rgb, hit, normal = _albedo_along(scene, sampler, ray, True)
                a_rgb, a_weight = np.asarray(a_rgb, np.float64), weight if hit else 0.0
                normal = np.asarray(normal, np.float64)
            values = np.concatenate([weight * rgb, [weight * alpha, weight], weight * rgb ** 2,
                                     a_weight * a_rgb, [a_weight, invalid],
                                     a_weight * normal])
            if halves:
                odd = weight * (s % 2)
                values = np.concatenate([values, odd * rgb, [odd]])
            if every:
                block.put(mi.ScalarPoint2f(px, py) + offset, [float(v) for v in values])
            else:
                sums[k] += values
            sampler.advance()
    if every:
        sums = np.array(block.tensor(), dtype=np.float64)[pixel_xy[:, 1], pixel_xy[:, 0]]
    return _read_sums(list(np.ascontiguousarray(sums.T)), integrator is not None)


#: The samples' kernels, replayed from a recording when the same trace repeats.
_DEVELOP = Replay(_develop_kernel)
