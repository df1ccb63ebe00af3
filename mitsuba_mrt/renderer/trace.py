"""Stage 2: tracing only the sampled pixels, with their ids (Mitsuba-specific).

In a JIT variant (LLVM, CUDA) every sample of every traced pixel is one lane
of a single Dr.Jit wavefront.  The scalar variant has no wavefronts, so it
loops over the traced pixels in Python, calling the same helpers.

Besides the nested integrator's radiance, one extra ray through each pixel
centre gives the AOVs the reconstruction needs: the hit shape, the surface
albedo, and which point and spot lights the hit point sees.
"""

from __future__ import annotations

import re
import time
import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import MRTError
from ..types import SparseTrace
from ..runtime.jit import jit_workers

#: At most this many lights are tracked in the ``visible_lights`` bit mask.
MAX_TRACKED_LIGHTS = 32
#: Specular (mirror) bounces followed by the id trace.
MIRROR_DEPTH = 4


def has_mirrors(scene: mi.Scene) -> bool:
    """True if a shape of ``scene`` has a purely specular (delta) BSDF."""
    return any(_is_mirror_bsdf(shape.bsdf()) for shape in scene.shapes())


#: Shape types whose mirror reflections keep their size (planar mirrors).
PLANAR_TYPES = ("Rectangle", "Disk")


def curved_mirror_indices(scene: mi.Scene) -> np.ndarray:
    """1-based indices (as in :func:`ordered_shapes`) of mirrors that are not planar.

    A curved mirror minifies what it reflects: its reflected regions can be
    thinner than the traced grid, so refinement traces its pixels in full.
    Meshes count as curved (their facets may point anywhere).
    """
    planar = {getattr(mi.ShapeType, name) for name in PLANAR_TYPES}
    return np.array([k + 1 for k, shape in enumerate(ordered_shapes(scene))
                     if _is_mirror_bsdf(shape.bsdf()) and shape.shape_type() not in planar],
                    dtype=np.int64)


def _is_mirror_bsdf(bsdf) -> bool:
    flags = int(bsdf.flags()) if bsdf is not None else 0
    return mi.has_flag(flags, mi.BSDFFlags.Delta) and not mi.has_flag(flags, mi.BSDFFlags.Smooth)


def _is_mirror(bsdf, valid):
    flags = bsdf.flags()
    delta = mi.has_flag(flags, mi.BSDFFlags.Delta)
    smooth = mi.has_flag(flags, mi.BSDFFlags.Smooth)
    if is_jit():
        return valid & delta & ~smooth
    return bool(valid and delta and not smooth)


def _follow_mirrors(scene, ray, si, valid):
    """Follow specular bounces from the first hit.

    Returns the final (non-mirror) hit, its validity, the specular
    throughput, and per bounce (bounced, shape pointer or object).
    """
    ctx = mi.BSDFContext()
    throughput = mi.Color3f(1.0)
    chain = []
    ray = mi.Ray3f(ray)
    for _ in range(MIRROR_DEPTH):
        if not is_jit() and not valid:
            break
        bsdf = si.bsdf(ray)
        mirror = _is_mirror(bsdf, valid)
        if not is_jit() and not mirror:
            break
        bs, weight = bsdf.sample(ctx, si, 0.5, mi.Point2f(0.5, 0.5), mirror)
        new_ray = si.spawn_ray(si.to_world(bs.wo))
        new_si = scene.ray_intersect(new_ray, mirror)
        if is_jit():
            throughput = dr.select(mirror, throughput * weight, throughput)
            chain.append((mirror, dr.select(mirror, dr.reinterpret_array(mi.UInt32, new_si.shape),
                                            mi.UInt32(0))))
            ray = dr.select(mirror, new_ray, ray)
            si = dr.select(mirror, new_si, si)
            valid = dr.select(mirror, new_si.is_valid(), valid)
        else:
            throughput = throughput * weight
            chain.append((True, new_si.shape if new_si.is_valid() else None))
            ray, si, valid = new_ray, new_si, bool(new_si.is_valid())
    return ray, si, valid, throughput, chain


def tracked_lights(scene: mi.Scene) -> list:
    """The scene's point and spot lights (delta position), at most 32."""
    lights = [e for e in scene.emitters()
              if mi.has_flag(e.flags(), mi.EmitterFlags.DeltaPosition)]
    return lights[:MAX_TRACKED_LIGHTS]


def is_jit() -> bool:
    """True in a JIT variant (LLVM, CUDA), False in a scalar one."""
    return dr.is_jit_v(mi.Float)


def logical_not(mask):
    """``~mask`` for Dr.Jit masks, ``not mask`` for the scalar variant's bools."""
    return ~mask if is_jit() else not mask


def _to_numpy(value, width: int) -> np.ndarray:
    """A Dr.Jit Color3f/Float as (width, 3)/(width,) numpy, literals broadcast."""
    arr = np.asarray(value)
    if arr.ndim == 2:
        return np.broadcast_to(arr.T, (width, arr.shape[0])).astype(np.float64)
    return np.broadcast_to(arr, (width,)).copy()


def _camera_ray(sensor, sampler, pixel, spp: int, centre: bool = False):
    """A camera ray through ``pixel`` (+ a sample offset, or the pixel centre)."""
    film_size = mi.ScalarVector2f(sensor.film().crop_size())
    offset = mi.Point2f(0.5, 0.5) if centre else sampler.next_2d()
    position = (pixel + offset) / film_size
    aperture = sampler.next_2d() if (sensor.needs_aperture_sample() and not centre) \
        else mi.Point2f(0.5, 0.5)
    ray_time = sensor.shutter_open()
    if sensor.shutter_open_time() > 0 and not centre:
        ray_time += sampler.next_1d() * sensor.shutter_open_time()
    wavelength = sampler.next_1d() if (mi.is_spectral and not centre) else 0.0
    ray, weight = sensor.sample_ray_differential(ray_time, wavelength, position, aperture)
    ray.scale_differential(dr.rsqrt(float(spp)))
    return ray, weight


def shadow_rule(scene: mi.Scene, lights: list) -> str:
    """How light visibility is found: ``rays``, or without shadow rays.

    ``none`` (no point or spot light), ``facing`` (a single sphere: a point
    sees a light exactly when it faces it, as a shadow ray would find) or
    ``always`` (a single planar shape never blocks a light from itself).
    """
    if not lights:
        return "none"
    shapes = scene.shapes()
    if len(shapes) == 1:
        kind = shapes[0].shape_type()
        if kind == int(mi.ShapeType.Sphere):
            return "facing"
        if kind in (int(mi.ShapeType.Rectangle), int(mi.ShapeType.Disk)):
            return "always"
    return "rays"


def _surface_aovs(scene, ray, lights, rule="rays", mirrors=False):
    """The id AOVs of the first hit of ``ray``.

    Returns (first hit, its validity, albedo, visible-light bit mask,
    mirror chain).  With ``mirrors``, specular bounces are followed first:
    albedo and light visibility are those of the final hit (the albedo
    times the mirrors' reflectance), and the chain lists the bounces.
    """
    first = si = scene.ray_intersect(ray)
    first_valid = valid = si.is_valid()
    chain = []
    throughput = mi.Color3f(1.0)
    if mirrors:
        ray, si, valid, throughput, chain = _follow_mirrors(scene, ray, si, valid)
    bsdf = si.bsdf(ray)
    albedo = bsdf.eval_diffuse_reflectance(si, valid) if (is_jit() or valid) \
        else mi.Color3f(0.0)
    albedo = dr.select(valid, throughput * albedo, 0.0)
    mask = mi.UInt32(0)
    for k, light in enumerate(lights):
        if not (is_jit() or valid):
            break
        ds, spec = light.sample_direction(si, mi.Point2f(0.5, 0.5), valid)
        if rule == "rays":
            blocked = scene.ray_test(si.spawn_ray_to(ds.p), valid)
        elif rule == "facing":
            blocked = dr.dot(si.n, ds.d) <= 0.0
        else:
            blocked = mi.Bool(False) if is_jit() else False
        lit = valid & logical_not(blocked) & (dr.max(spec) > 0.0)
        mask |= dr.select(lit, mi.UInt32(1 << k), mi.UInt32(0))
    return first, first_valid, albedo, mask, chain


def _path_ids(shape_index: np.ndarray, steps: list, num_shapes: int) -> np.ndarray:
    """One integer per pixel for the chain of shapes along its mirror bounces.

    Each step is 0 (no bounce), a 1-based shape index, or ``num_shapes + 1``
    (reflected into the background); the digits are combined in base
    ``num_shapes + 2``, folded into 31 bits by a hash when they do not fit.
    """
    path = shape_index.astype(np.int64).copy()
    base = num_shapes + 2
    fits = base ** (len(steps) + 1) < (1 << 31)
    for step in steps:
        path = path * base + step if fits else (path * 1000003 + step) % ((1 << 31) - 1)
    return path


def _natural_key(text: str):
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", text)]


def ordered_shapes(scene: mi.Scene) -> list:
    """The scene's shapes in id order (natural sort of ``shape.id()``).

    ``scene.shapes()`` is not in file order, and the paper's id rule and
    smoothing depend on the order, so shapes are numbered by their ``id``
    attributes: ``sphere_2`` before ``sphere_10``; the bundled scenes name
    their shapes in the report's table order.
    """
    shapes = list(scene.shapes())
    order = sorted(range(len(shapes)), key=lambda k: (_natural_key(shapes[k].id()), k))
    return [shapes[k] for k in order]


def _shape_lookup(scene: mi.Scene):
    """Map from Dr.Jit shape pointers (JIT) or shape objects (scalar) to 1-based indices."""
    shapes = ordered_shapes(scene)
    if is_jit():
        keys = np.array([int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(s))[0])
                         for s in shapes], dtype=np.int64)
        order = np.argsort(keys)
        return keys[order], order + 1
    return {id(s): k + 1 for k, s in enumerate(shapes)}


def trace_pixels(scene: mi.Scene, sensor: mi.Sensor, integrator: mi.Integrator,
                 pixel_xy: np.ndarray, spp: int, seed: int = 0, aovs: bool = True,
                 radiance: bool = True) -> SparseTrace:
    """Render only ``pixel_xy`` with ``integrator``, plus the id AOVs.

    Parameters
    ----------
    scene, sensor : Mitsuba scene and the sensor to render from.
    integrator : mi.SamplingIntegrator
        The nested integrator (``matte``, ``direct``, ``path``, ...).
    pixel_xy : ndarray of int, shape (n, 2)
        (column, row) of the pixels to trace, row 0 at the top.
    spp : int
        Samples per traced pixel (averaged, as a box pixel filter does).
    seed : int
        Seed of the sampler.
    aovs : bool
        Also trace the id AOVs (albedo, shape, visible lights); without
        them those fields are zero and only the radiance costs time.
    radiance : bool
        Run the nested integrator; without it the radiance is zero and only
        the id AOVs cost time (the MRT's cheap full-resolution id pass).
    """
    if not isinstance(integrator, mi.SamplingIntegrator):
        raise MRTError(f"the nested integrator must be a sampling integrator, got {integrator}")
    pixel_xy = np.asarray(pixel_xy, dtype=np.int64)
    spp = int(spp)
    if spp < 1:
        raise MRTError(f"spp must be >= 1, got {spp}")
    start = time.perf_counter()
    lights = tracked_lights(scene)
    lookup = _shape_lookup(scene)
    rule = shadow_rule(scene, lights)
    sampler = sensor.sampler().clone()
    sampler.set_sample_count(spp)
    spp = sampler.sample_count()
    with jit_workers():  # all of Dr.Jit's threads, also inside a reconstruction
        trace = (_trace_jit if is_jit() else _trace_scalar)(
            scene, sensor, integrator if radiance else None, sampler, pixel_xy, spp, seed,
            lights, lookup, aovs, rule)
    radiance, albedo, shape_index, visible, path_id = trace
    curved = curved_mirror_indices(scene) if aovs else np.zeros(0, np.int64)
    return SparseTrace(radiance, albedo, shape_index, visible, len(lights), spp,
                       time.perf_counter() - start, shadow_rays=rule == "rays", path_id=path_id,
                       curved_mirror=np.isin(shape_index, curved) if len(curved) else None)


def _trace_jit(scene, sensor, integrator, sampler, pixel_xy, spp, seed, lights, lookup, aovs,
               rule):
    n = len(pixel_xy)
    sampler.set_samples_per_wavefront(spp)
    sampler.seed(seed, n * spp)
    columns, rows = mi.Float(pixel_xy[:, 0]), mi.Float(pixel_xy[:, 1])
    if integrator is None:
        radiance = np.zeros((n, 3))
    elif spp == 1:
        pixel = mi.Point2f(columns, rows)
    else:  # lanes pixel-major, as Mitsuba's own render loop lays them out
        owner = dr.arange(mi.UInt32, n * spp) // spp
        pixel = mi.Point2f(dr.gather(mi.Float, columns, owner), dr.gather(mi.Float, rows, owner))
    if integrator is not None:
        ray, weight = _camera_ray(sensor, sampler, pixel, spp)
        radiance, _, _ = integrator.sample(scene, sampler, ray, None, True)
        radiance = mi.Color3f(weight * radiance)
        # Evaluate once: block_sum reduces each channel on its own, and on an
        # unevaluated radiance each reduction would re-run the integrator.
        dr.eval(radiance)
        if spp > 1:
            radiance = dr.block_sum(radiance, spp) / spp
            dr.eval(radiance)
        radiance = _to_numpy(radiance, n)
    if not aovs:
        zero = np.zeros(n, np.int64)
        return radiance, np.zeros((n, 3)), zero, np.zeros(n, np.uint32), zero

    ray, _ = _camera_ray(sensor, sampler, mi.Point2f(columns, rows), 1, centre=True)
    si, valid, albedo, mask, chain = _surface_aovs(scene, ray, lights, rule, has_mirrors(scene))
    pointers = dr.reinterpret_array(mi.UInt32, si.shape)
    dr.eval(albedo, mask, pointers, chain)
    keys, indices = lookup

    def to_index(ptr):
        ptr = _to_numpy(ptr, n).astype(np.int64)
        if not len(keys):
            return np.zeros(n, dtype=np.int64)
        pos = np.clip(np.searchsorted(keys, ptr), 0, len(keys) - 1)
        return np.where(keys[pos] == ptr, indices[pos], 0).astype(np.int64)

    shape_index = to_index(pointers)
    steps = [np.where(_to_numpy(bounced, n).astype(bool),
                      np.where(to_index(ptr) > 0, to_index(ptr), len(keys) + 1), 0)
             for bounced, ptr in chain]
    return (radiance, _to_numpy(albedo, n), shape_index,
            _to_numpy(mask, n).astype(np.uint32), _path_ids(shape_index, steps, len(keys)))


def _trace_scalar(scene, sensor, integrator, sampler, pixel_xy, spp, seed, lights, lookup, aovs,
                  rule):
    n = len(pixel_xy)
    radiance = np.zeros((n, 3))
    albedo = np.zeros((n, 3))
    shape_index = np.zeros(n, dtype=np.int64)
    visible = np.zeros(n, dtype=np.uint32)
    mirrors = has_mirrors(scene)
    steps = [np.zeros(n, dtype=np.int64) for _ in range(MIRROR_DEPTH if mirrors else 0)]
    for k, (x, y) in enumerate(pixel_xy.tolist()):
        sampler.seed((seed * 0x9E3779B1 + k) & 0xFFFFFFFF)  # a 32-bit seed per pixel
        pixel = mi.Point2f(x, y)
        for _ in range(spp if integrator is not None else 0):
            ray, weight = _camera_ray(sensor, sampler, pixel, spp)
            value, _, _ = integrator.sample(scene, sampler, ray, None, True)
            radiance[k] += np.asarray(weight * value, dtype=np.float64)
            sampler.advance()
        if not aovs:
            continue
        ray, _ = _camera_ray(sensor, sampler, pixel, 1, centre=True)
        si, valid, alb, mask, chain = _surface_aovs(scene, ray, lights, rule, mirrors)
        if valid:
            albedo[k] = np.asarray(alb, dtype=np.float64)
            shape_index[k] = lookup.get(id(si.shape), 0)
            visible[k] = int(mask)
            for b, (_, shape) in enumerate(chain):
                steps[b][k] = lookup.get(id(shape), 0) if shape is not None else len(lookup) + 1
    return (radiance / spp, albedo, shape_index, visible,
            _path_ids(shape_index, steps, len(lookup)))
