"""Stage 2: tracing only the sampled pixels, with their ids (Mitsuba-specific).

A traced pixel is what ``mi.render`` gives at that pixel: its samples
follow the film's reconstruction filter (:mod:`.pixel_filter`) and are
developed as Mitsuba's own image block does, spectra converted to the RGB
that ``mi.render`` writes, alpha included.  In a JIT variant (LLVM, CUDA)
every sample of every traced pixel is one lane of a single Dr.Jit
wavefront; the scalar variant loops over the samples in Python.

Each sample also gives the albedo of its first hit, the directional albedo
of the BSDF for the view direction (the mean weight of a BSDF sample),
averaged like the radiance: what multiplies the incoming light, bounded by
one.  One extra ray through each pixel centre gives the ids: the hit shape,
the mirror chain, and which point and spot lights the hit point sees.
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass
from typing import Callable

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import MRTError
from ..types import SparseTrace
from ..runtime.jit import jit_workers
from .pixel_filter import filter_table
from .replay import Replay, padded_size
from .replay import active as replay_active

#: At most this many lights are tracked in the ``visible_lights`` bit mask.
MAX_TRACKED_LIGHTS = 32
#: Specular (mirror) bounces followed by the id trace.
MIRROR_DEPTH = 4


def has_mirrors(scene: mi.Scene) -> bool:
    """True if a shape of ``scene`` (one inside a shape group included) has a
    purely specular (delta) BSDF."""
    return any(shows(scene, lambda shape: _is_mirror_bsdf(shape.bsdf()), any))


def shows(scene: mi.Scene, test: Callable, combine: Callable = any) -> list[bool]:
    """Per shape in :func:`ordered_shapes` order, ``combine`` (``any`` or
    ``all``) of ``test`` over the shapes whose BSDFs it shows.

    A shape shows its own; an ``instance`` shows the shapes of its
    ``shapegroup`` (its own BSDF is a default diffuse that no ray meets).
    Mitsuba does not say which group an instance refers to: where the groups
    differ in ``test``, it is found by bounding box (the group's box carried
    by the instance's transform is the instance's box), and where that
    leaves several groups (or none), the instance shows the shapes of all
    candidates (or of every group).
    """
    shapes = ordered_shapes(scene)
    instance = [shape.class_name() == "Instance" for shape in shapes]
    groups = _shape_groups(scene) if any(instance) else []
    verdicts = {combine(test(inner) for inner in members) for _, members in groups}

    def verdict(shape, inst: bool) -> bool:
        if not inst or not groups:
            return bool(test(shape))
        if len(verdicts) == 1:
            return next(iter(verdicts))
        return combine(test(inner) for inner in _instance_surfaces(shape, groups))

    return [verdict(shape, inst) for shape, inst in zip(shapes, instance)]


def _shape_groups(scene: mi.Scene) -> list[tuple]:
    """The scene's shape groups as (bounding box corners (8, 3), inner shapes)."""
    def shapes_below(node) -> list:
        found = []

        class Collect(mi.TraversalCallback):
            def put(self, name, value, *flags):
                if isinstance(value, mi.Shape):
                    found.append(value)

        node.traverse(Collect())
        return found

    listed = scene.shapes()  # held, so that the traversal meets these very objects
    known = {id(shape) for shape in listed}
    groups = []
    for node in shapes_below(scene):
        if id(node) not in known and node.class_name() != "Instance":
            groups.append((_box_corners(node.bbox()), shapes_below(node)))
    return groups


def _box_corners(box) -> np.ndarray:
    low, high = np.ravel(box.min).astype(np.float64), np.ravel(box.max).astype(np.float64)
    pick = np.array([[(k >> a) & 1 for a in range(3)] for k in range(8)], dtype=bool)
    return np.where(pick, high, low)


def _instance_surfaces(instance, groups: list[tuple]) -> list:
    """The shapes of the groups whose box, moved by ``instance``'s transform, is its box."""
    to_world = np.asarray(mi.traverse(instance)["to_world"].matrix,
                          dtype=np.float64).reshape(4, 4)
    box = _box_corners(instance.bbox())
    low, high = box.min(axis=0), box.max(axis=0)
    tolerance = 1e-4 * max(1.0, float(np.abs(box).max()))
    matches = []
    for corners, inner in groups:
        moved = corners @ to_world[:3, :3].T + to_world[:3, 3]
        if (np.abs(moved.min(axis=0) - low).max() <= tolerance
                and np.abs(moved.max(axis=0) - high).max() <= tolerance):
            matches.append(inner)
    return [shape for inner in (matches or [inner for _, inner in groups]) for shape in inner]


#: Shape types whose mirror reflections keep their size (planar mirrors).
PLANAR_TYPES = ("Rectangle", "Disk")


def curved_mirror_indices(scene: mi.Scene) -> np.ndarray:
    """1-based indices (as in :func:`ordered_shapes`) of mirrors that are not planar.

    A curved mirror minifies what it reflects: its reflected regions can be
    thinner than the traced grid, so refinement traces its pixels in full.
    Meshes count as curved (their facets may point anywhere).
    """
    planar = {getattr(mi.ShapeType, name) for name in PLANAR_TYPES}
    curved = shows(scene, lambda shape: (_is_mirror_bsdf(shape.bsdf())
                                         and shape.shape_type() not in planar))
    return np.flatnonzero(curved).astype(np.int64) + 1


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


def _hit_shape(si):
    """The shape ``si`` hit as the scene lists it: for a hit on an instance
    of a shape group, the instance (the shape inside the group is shared by
    all instances, and the scene does not list it); a Dr.Jit pointer (as
    ``UInt32``) in JIT variants, the object in scalar ones."""
    if is_jit():
        instance = dr.reinterpret_array(mi.UInt32, si.instance)
        return dr.select(instance != 0, instance, dr.reinterpret_array(mi.UInt32, si.shape))
    return si.instance if si.instance is not None else si.shape


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
            chain.append((mirror, dr.select(mirror, _hit_shape(new_si), mi.UInt32(0))))
            ray = dr.select(mirror, new_ray, ray)
            si = dr.select(mirror, new_si, si)
            valid = dr.select(mirror, new_si.is_valid(), valid)
        else:
            throughput = throughput * weight
            chain.append((True, _hit_shape(new_si) if new_si.is_valid() else None))
            ray, si, valid = new_ray, new_si, bool(new_si.is_valid())
    return ray, si, valid, throughput, chain


def replayable(scene: mi.Scene) -> bool:
    """Whether a trace of ``scene`` can be replayed (:mod:`.replay`): not in a
    spectral or polarized variant (their colour tables are not among a
    trace's inputs) and not without shapes (Dr.Jit finds no instance for the
    intersection's virtual calls then)."""
    return not (mi.is_spectral or mi.is_polarized) and len(scene.shapes()) > 0


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


def _camera_ray(sensor, sampler, position, spp: int, centre: bool = False):
    """A camera ray through ``position`` (crop-relative pixel coordinates).

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
    ray.scale_differential(dr.rsqrt(float(spp)))
    return ray, weight


def _rgb(value, wavelengths, active=True):
    """A sample's value as the RGB that ``mi.render`` develops (spectra converted)."""
    if mi.is_polarized:
        value = mi.unpolarized_spectrum(value)
    if mi.is_spectral:
        return mi.spectrum_to_srgb(value, wavelengths, active)
    return mi.Color3f(value)


def _albedo_along(scene, sampler, ray, active):
    """What multiplies the light arriving at the first hit: its BSDF's albedo
    for the view direction, one BSDF sample's weight, clamped to [0, 1] (RGB);
    with whether the camera ray hit and the shading normal at its hit.

    Through mirrors and glass (delta BSDFs) the path is followed, up to
    ``MIRROR_DEPTH`` bounces, and the albedo is that of the surface seen
    times the specular throughput; 0 on a miss.  The mean over a pixel's
    samples estimates the pixel's albedo the way its radiance is estimated.
    """
    albedo = mi.Color3f(0.0)
    throughput = mi.Color3f(1.0)
    ray = mi.Ray3f(ray)
    active = mi.Bool(active) if is_jit() else bool(active)
    hit, normal = None, None
    for depth in range(MIRROR_DEPTH + 1):
        si = scene.ray_intersect(ray, active)
        valid = active & si.is_valid() if is_jit() else bool(active and si.is_valid())
        if depth == 0:
            hit = valid
            normal = dr.select(valid, si.sh_frame.n, 0.0) if is_jit() else (
                si.sh_frame.n if valid else mi.Vector3f(0.0))
        if not (is_jit() or valid):
            break
        bsdf = si.bsdf(ray)
        bs, weight = bsdf.sample(mi.BSDFContext(), si, sampler.next_1d(valid),
                                 sampler.next_2d(valid), valid)
        weight = dr.clip(_rgb(weight, si.wavelengths, valid), 0.0, 1.0)
        delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
        done = valid & (bs.pdf > 0.0) & (logical_not(delta) if depth < MIRROR_DEPTH else True)
        albedo = dr.select(done, throughput * weight, albedo)
        if not is_jit() and done:
            break
        active = valid & (bs.pdf > 0.0) & logical_not(done)
        throughput = throughput * weight
        ray = si.spawn_ray(si.to_world(bs.wo))
    return albedo, hit, normal


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

    Returns (first hit, its validity, visible-light bit mask, mirror
    chain).  With ``mirrors``, specular bounces are followed first: light
    visibility is that of the final hit, and the chain lists the bounces.
    """
    first = si = scene.ray_intersect(ray)
    first_valid = valid = si.is_valid()
    chain = []
    if mirrors:
        ray, si, valid, _, chain = _follow_mirrors(scene, ray, si, valid)
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
    return first, first_valid, mask, chain


def _fold(path: np.ndarray, digit) -> np.ndarray:
    """``digit`` folded into ``path`` ids by a hash that keeps them in 31 bits."""
    return (path * 1000003 + digit) % ((1 << 31) - 1)


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
        path = path * base + step if fits else _fold(path, step)
    return path


#: Shapes inside shape groups, by address: a number each, given on first
#: sight (the scene does not list them, so they have no index of their own).
_inner_shapes: dict = {}


def _with_inner_shapes(path: np.ndarray, inner: np.ndarray) -> np.ndarray:
    """``path`` ids told apart by the shape inside an instance's group.

    An instance is one listed shape, but its group may hold several (a cup
    and the ball in it): where ``inner`` (the address of the shape hit inside
    the group, 0 elsewhere) is set, its number is folded into the path id
    (:func:`_fold`, as :func:`_path_ids` folds long chains).  Numbers
    stay fixed for the process, so ids agree between the traces of a render.
    """
    hit = inner != 0
    if not hit.any():
        return path
    addresses, which = np.unique(inner[hit], return_inverse=True)
    numbers = np.array([_inner_shapes.setdefault(int(a), len(_inner_shapes) + 1)
                        for a in addresses], dtype=np.int64)
    out = path.copy()
    out[hit] = _fold(path[hit], numbers[which])
    return out


def _natural_key(text: str):
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", text)]


def diffuse_shapes(scene: mi.Scene) -> np.ndarray:
    """Per shape index (1-based, as in :func:`ordered_shapes`; entry 0 for no
    shape), whether the shape's BSDF is purely diffuse (an instance's: all
    those of its group's shapes): its albedo is then its reflectance at the
    hit, exact for every sample."""
    other = (mi.BSDFFlags.Glossy, mi.BSDFFlags.Delta, mi.BSDFFlags.Transmission)

    def diffuse(bsdf) -> bool:
        flags = int(bsdf.flags()) if bsdf is not None else 0
        return (mi.has_flag(flags, mi.BSDFFlags.DiffuseReflection)
                and not any(mi.has_flag(flags, f) for f in other))

    return np.array([False] + shows(scene, lambda shape: diffuse(shape.bsdf()), all), dtype=bool)


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


#: Samples per pixel of an albedo-only pass (the id pass).  A pixel traced
#: with the nested integrator takes its albedo from all of its samples, the
#: same ones as its radiance, so that the two see the same footprint.
ALBEDO_SAMPLES = 16

#: Albedo (per channel) below which a pixel is not demodulated: dividing by
#: it would turn the noise of a nearly black surface into huge values.  Dark
#: textures go far lower (black in an sRGB PNG is about 0.003 linear), and
#: their pixels must be demodulated like their bright neighbours.
ALBEDO_MIN = 0.001

#: A pixel's sample variance below this share of its samples' mean square is
#: taken as 0: the sums are float32, so their difference rounds to ~1e-7 of it.
VARIANCE_FLOOR = 1e-6

#: Channels of the image block the samples are developed in: weighted RGB,
#: alpha, the weight, RGB squared (for the variance), albedo and its weight,
#: the count of samples whose radiance was NaN or Inf, and the shading normal
#: (weighted as the albedo).
_CHANNELS = 16


@dataclass
class _Developed:
    """Per traced pixel, what its samples gave (numpy)."""

    radiance: np.ndarray  # (n, 3) the developed RGB
    alpha: np.ndarray     # (n,)
    variance: np.ndarray  # (n, 3) of a single sample's RGB about the pixel's mean
    albedo: np.ndarray    # (n, 3)
    normal: np.ndarray | None = None  # (n, 3) the samples' mean shading normal


def trace_pixels(scene: mi.Scene, sensor: mi.Sensor, integrator: mi.Integrator,
                 pixel_xy: np.ndarray, spp: int, seed: int = 0, aovs: bool = True,
                 radiance: bool = True, replay: bool = False,
                 pad: bool = False, box: bool = False, ids: bool = True) -> SparseTrace:
    """Render only ``pixel_xy`` with ``integrator``, plus the id AOVs.

    Parameters
    ----------
    scene, sensor : Mitsuba scene and the sensor to render from.
    integrator : mi.SamplingIntegrator
        The nested integrator (``matte``, ``direct``, ``path``, ...).
    pixel_xy : ndarray of int, shape (n, 2)
        (column, row) of the pixels to trace within the film's crop window,
        row 0 at the top.
    spp : int
        Samples per traced pixel (>= 1).
    seed : int
        Seed of the sampler.
    aovs : bool
        Also trace the AOVs (albedo, shape, visible lights); without them
        those fields are zero and only the radiance costs time.
    radiance : bool
        Run the nested integrator; without it the radiance is zero and only
        the AOVs cost time (the MRT's cheap full-resolution id pass).
    replay : bool
        Record the kernels (:func:`drjit.freeze`) and replay them when this
        scene, sensor and integrator are traced again with as many pixels
        and samples, instead of tracing the integrator anew: for the pixel
        sets every render of an image traces (the grid, the id pass), not
        for one-off sets, which would only be recorded (:mod:`.replay`; sets
        of a size that varies: ``pad``).
    pad : bool
        For sets whose size changes from render to render (``refine``'s
        edges): trace the set padded with copies of its first pixel to the
        next size of :func:`.replay.padded_size`'s few, recorded once and
        replayed after.  The pixels' values are those of the set traced
        unpadded: Mitsuba's samplers seed each sample by its index.
    box : bool
        Develop the samples with a box pixel filter instead of the film's:
        every pixel from the samples inside it alone, so that no two pixels
        share a sample (what a denoiser wants of a full render).
    ids : bool
        With ``aovs``: also the ids (one ray through each pixel's centre), and
        the normal at that centre; without: no ids, and the normal of the
        samples' own first hits (a denoiser's guide, as their albedo is).
    """
    if not isinstance(integrator, mi.SamplingIntegrator):
        raise MRTError(f"the nested integrator must be a sampling integrator, got {integrator}")
    pixel_xy = np.asarray(pixel_xy, dtype=np.int64)
    n = len(pixel_xy)
    if pad and n and is_jit() and replay_active() and replayable(scene):
        size = padded_size(n)
        padded = np.concatenate([pixel_xy, np.repeat(pixel_xy[:1], size - n, axis=0)])
        return trace_pixels(scene, sensor, integrator, padded, spp, seed, aovs, radiance,
                            replay=True, box=box, ids=ids).take(slice(0, n))
    start = time.perf_counter()
    lights = tracked_lights(scene)
    rule = shadow_rule(scene, lights)
    sampler = sensor.sampler().clone()
    sampler.set_sample_count(int(spp))
    spp = sampler.sample_count()
    replay = replay and is_jit() and replayable(scene)
    zero = np.zeros(n, np.int64)
    with jit_workers():  # all of Dr.Jit's threads, also inside a reconstruction
        develop = _develop_jit if is_jit() else _develop_scalar
        if radiance:
            samples = develop(scene, sensor, integrator, sampler, pixel_xy, spp, seed, aovs,
                              replay, box)
        elif aovs:
            sampler.set_sample_count(min(spp, ALBEDO_SAMPLES))
            samples = develop(scene, sensor, None, sampler, pixel_xy, sampler.sample_count(),
                              seed, True, replay, box)
        if aovs and ids:
            shape_index, visible, path_id, normal = (_ids_jit if is_jit() else _ids_scalar)(
                scene, sensor, sampler, pixel_xy, lights, _shape_lookup(scene), rule, replay)
        elif aovs:
            shape_index, visible, path_id = zero, np.zeros(n, np.uint32), zero
            normal = samples.normal
        else:
            shape_index, visible, path_id, normal = zero, np.zeros(n, np.uint32), zero, None
    if not (radiance or aovs):
        samples = _Developed(np.zeros((n, 3)), np.zeros(n), np.zeros((n, 3)), np.zeros((n, 3)))
    if aovs and ids:  # only a surface seen at the pixel's centre is demodulated
        samples.albedo[shape_index == 0] = 0.0
    if aovs:  # and not a black one
        samples.albedo[samples.albedo < ALBEDO_MIN] = 0.0
    curved = curved_mirror_indices(scene) if aovs and ids else np.zeros(0, np.int64)
    return SparseTrace(samples.radiance if radiance else np.zeros((n, 3)),
                       samples.albedo if aovs else np.zeros((n, 3)), shape_index, visible,
                       len(lights), spp, time.perf_counter() - start,
                       shadow_rays=rule == "rays", path_id=path_id,
                       curved_mirror=np.isin(shape_index, curved) if len(curved) else None,
                       alpha=samples.alpha if radiance else None,
                       variance=samples.variance if radiance else None, normal=normal)


def _read_sums(sums: np.ndarray, pixel_xy: np.ndarray) -> _Developed:
    """The developed values of the traced pixels from their filter-weighted sums."""
    def reciprocal(weight):  # 0 where nothing was accumulated
        out = np.zeros_like(weight)
        np.divide(1.0, weight, out=out, where=weight != 0.0)
        return out

    per_weight = reciprocal(sums[:, 4])[:, None]
    radiance = sums[:, 0:3] * per_weight
    second = sums[:, 5:8] * per_weight
    per_albedo_weight = reciprocal(np.maximum(sums[:, 11], 0.0))[:, None]
    albedo = sums[:, 8:11] * per_albedo_weight
    radiance[sums[:, 12] > 0.0] = np.nan  # reported by the caller's check, as a full render's
    variance = second - radiance ** 2
    # below this it is the float32 sums' rounding (a single sample's is all rounding)
    variance[~(variance > VARIANCE_FLOOR * second)] = 0.0
    return _Developed(radiance, sums[:, 3] * per_weight[:, 0], variance,
                      np.clip(albedo, 0.0, 1.0),
                      np.clip(sums[:, 13:16] * per_albedo_weight, -1.0, 1.0))


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


def _aligned_float(values: np.ndarray):
    """``values`` as a Dr.Jit ``Float`` over a float32 copy aligned to :data:`ALIGNMENT`.

    Dr.Jit maps a NumPy array's memory instead of copying it, and a frozen
    call (:mod:`.replay`) is recorded anew whenever an input's memory turns
    from aligned to unaligned or back: NumPy's buffers are aligned or not by
    chance, so the same trace was recorded again on some renders.
    """
    values = np.asarray(values, dtype=np.float32).ravel()
    slack = ALIGNMENT // values.itemsize
    buffer = np.empty(len(values) + slack, dtype=np.float32)
    start = (-buffer.ctypes.data % ALIGNMENT) // values.itemsize
    out = buffer[start:start + len(values)]
    out[...] = values
    return mi.Float(out)


def _develop_jit(scene, sensor, integrator, sampler, pixel_xy, spp, seed, albedo, replay,
                 box=False):
    """Trace ``spp`` samples of every pixel in one wavefront and develop them.

    Every pixel of the image: as ``mi.render`` does (uniform over each pixel,
    splatted with the filter).  Some pixels: each from its own samples, placed
    with the filter's distribution (:mod:`.pixel_filter`).  ``sampler`` is
    :func:`_develop_scalar`'s; the kernels clone the sensor's own.
    """
    film = sensor.film()
    width, height = (int(v) for v in film.crop_size())
    table = filter_table(box_filter() if box else film.rfilter())
    n = len(pixel_xy)
    every = _every_pixel(pixel_xy, width, height)
    # what the kernels bake in, so that a recording is replayed only where it holds
    layout = (n, int(spp), integrator is not None, bool(albedo), every, width, height,
              tuple(int(v) for v in film.crop_offset()), bool(film.sample_border()),
              float(table.radius), len(table.pdf), bool(box))
    sums = _DEVELOP(scene, sensor, integrator, _aligned_float(pixel_xy[:, 0]),
                    _aligned_float(pixel_xy[:, 1]), _aligned_float(table.cdf),
                    dr.opaque(mi.UInt32, seed & 0xFFFFFFFF), layout,
                    objects=(scene, sensor, integrator), record=replay)
    if every:
        sums = sums.numpy().astype(np.float64)[pixel_xy[:, 1], pixel_xy[:, 0]]
    else:
        sums = np.stack([np.broadcast_to(np.asarray(total, dtype=np.float64), (n,))
                         for total in sums], axis=1)  # (literal zeros broadcast)
    return _read_sums(sums, pixel_xy)


def _develop_kernel(scene, sensor, integrator, pixel_x, pixel_y, cdf, seed, layout):
    """The kernels of :func:`_develop_jit`: the samples' filter-weighted sums,
    per pixel (a list of channels) or, for every pixel, as an image block's
    tensor.  Everything they depend on is an argument (``layout`` the Python
    values), so that :func:`drjit.freeze` can record and replay them.

    The sampler is made here, not passed: a frozen function's inputs are
    also its outputs, and the sampler's state after the samples would cost
    a second kernel over every lane to write back.
    """
    (n, spp, _, albedo, every, width, height, crop_offset, sample_border, radius, cells,
     box) = layout
    film = sensor.film()
    rfilter = box_filter() if box else film.rfilter()
    cell = 2.0 * radius / cells
    sampler = sensor.sampler().clone()
    sampler.set_sample_count(spp)
    sampler.set_samples_per_wavefront(spp)
    sampler.seed(seed, n * spp)
    owner = dr.arange(mi.UInt32, n * spp) // spp  # lanes pixel-major, as Mitsuba's own

    def offset(u):  # inverse CDF of the tabulated |filter|
        k = dr.binary_search(0, cells - 1, lambda i: dr.gather(mi.Float, cdf, i + 1) <= u)
        lo, hi = dr.gather(mi.Float, cdf, k), dr.gather(mi.Float, cdf, k + 1)
        t = dr.select(hi > lo, (u - lo) / (hi - lo), 0.5)
        return -radius + (mi.Float(k) + t) * cell

    u = sampler.next_2d()
    pixel = mi.Point2f(dr.gather(mi.Float, pixel_x, owner), dr.gather(mi.Float, pixel_y, owner))
    if every:
        position, weight = pixel + u, mi.Float(1.0)
    else:
        d = mi.Point2f(offset(u.x), offset(u.y))
        position = pixel + 0.5 + d
        # f / density is a constant of the filter's sign: the weight is that sign
        weight = dr.sign(rfilter.eval(d.x) * rfilter.eval(d.y))
    active = mi.Bool(True) if sample_border else (
        (position.x >= 0) & (position.x < width) & (position.y >= 0) & (position.y < height))
    weight = dr.select(active, weight, 0.0)

    ray, ray_weight = _camera_ray(sensor, sampler, position, spp)
    zero = mi.Float(0.0)
    rgb, alpha, invalid = mi.Color3f(0.0), zero, zero
    if integrator is not None:
        value, valid, _ = integrator.sample(scene, sampler, ray, None, active)
        rgb = _rgb(ray_weight * value, ray.wavelengths, active)
        finite = dr.all(dr.isfinite(rgb))
        invalid = dr.select(active & ~finite, 1.0, 0.0)
        rgb = dr.select(active & finite, rgb, 0.0)
        alpha = dr.select(active & valid, 1.0, 0.0)
    a_weight, a_rgb, normal = zero, mi.Color3f(0.0), mi.Vector3f(0.0)
    if albedo:  # averaged over the samples that hit a surface
        a_rgb, hit, normal = _albedo_along(scene, sampler, ray, active)
        a_weight = dr.select(active & hit, weight, 0.0)
    values = [weight * rgb.x, weight * rgb.y, weight * rgb.z, weight * alpha, weight,
              weight * rgb.x ** 2, weight * rgb.y ** 2, weight * rgb.z ** 2,
              a_weight * a_rgb.x, a_weight * a_rgb.y, a_weight * a_rgb.z, a_weight, invalid,
              a_weight * normal.x, a_weight * normal.y, a_weight * normal.z]
    # Evaluate once: each reduction below would otherwise re-run the integrator.
    dr.eval(values)
    if every:
        block = _new_block(film, rfilter)
        block.put(position + mi.ScalarVector2f(crop_offset), values, active)
        return block.tensor()
    sums = [dr.block_sum(value, spp) for value in values]
    dr.eval(sums)
    return sums


def _new_block(film, rfilter) -> mi.ImageBlock:
    return mi.ImageBlock(size=film.crop_size(), offset=film.crop_offset(),
                         channel_count=_CHANNELS, rfilter=rfilter, border=False)


#: The box pixel filter of each variant, made on first use.
_BOX_FILTERS: dict = {}


def box_filter():
    """Mitsuba's ``box`` reconstruction filter (radius half a pixel) in the active variant."""
    rfilter = _BOX_FILTERS.get(mi.variant())
    if rfilter is None:
        rfilter = _BOX_FILTERS[mi.variant()] = mi.load_dict({"type": "box"})
    return rfilter


def _develop_scalar(scene, sensor, integrator, sampler, pixel_xy, spp, seed, albedo,
                    replay=False, box=False):
    """The scalar variant's :func:`_develop_jit`: sample by sample in Python."""
    film = sensor.film()
    width, height = (int(v) for v in film.crop_size())
    rfilter = box_filter() if box else film.rfilter()
    table = filter_table(rfilter)
    every = _every_pixel(pixel_xy, width, height)
    offset = mi.ScalarVector2f(film.crop_offset())
    block = _new_block(film, rfilter) if every else None
    sums = np.zeros((len(pixel_xy), _CHANNELS))
    for k, (x, y) in enumerate(pixel_xy.tolist()):
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
                value, valid, _ = integrator.sample(scene, sampler, ray, None, True)
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
            if every:
                block.put(mi.ScalarPoint2f(px, py) + offset, [float(v) for v in values])
            else:
                sums[k] += values
            sampler.advance()
    if every:
        sums = np.array(block.tensor(), dtype=np.float64)[pixel_xy[:, 1], pixel_xy[:, 0]]
    return _read_sums(sums, pixel_xy)


#: What :func:`_with_side` folds into the path id of a surface seen from its back.
_BACK_SIDE = 0x5EED


def _with_side(path: np.ndarray, back: np.ndarray) -> np.ndarray:
    """``path`` ids told apart by the side of the surface seen.

    The inside and the outside of an open shape (a cup's wall, a sheet seen
    from both sides) are one shape, yet their light differs across the rim;
    where ``back`` (the ray meets the surface from behind its shading normal:
    the side a ``twosided`` material flips to, and that a one-sided one
    leaves black) is set, a constant is folded into the path id
    (:func:`_fold`).  A closed shape seen from outside is seen from its
    front, but for a few pixels at the silhouette of a coarse smooth-shaded
    mesh, which the material also sees from behind.
    """
    return np.where(back, _fold(path, _BACK_SIDE), path)


def _ids_jit(scene, sensor, sampler, pixel_xy, lights, lookup, rule, replay):
    """Shape, visible lights, mirror chain and side of every pixel's centre ray."""
    n = len(pixel_xy)
    layout = (n, rule, has_mirrors(scene), tuple(int(v) for v in sensor.film().crop_size()))
    mask, pointers, inner, chain, normal, back = _IDS(
        scene, sensor, lights, _aligned_float(pixel_xy[:, 0]), _aligned_float(pixel_xy[:, 1]),
        layout, objects=(scene, sensor), record=replay)
    keys, indices = lookup

    def to_index(ptr):
        ptr = _to_numpy(ptr, n).astype(np.int64)
        if not len(keys):
            return np.zeros(n, dtype=np.int64)
        pos = np.clip(np.searchsorted(keys, ptr), 0, len(keys) - 1)
        return np.where(keys[pos] == ptr, indices[pos], 0).astype(np.int64)

    shape_index = to_index(pointers)
    steps = [np.where(_to_numpy(bounced, n).astype(bool),
                      np.where((index := to_index(ptr)) > 0, index, len(keys) + 1), 0)
             for bounced, ptr in chain]
    path = _with_inner_shapes(_path_ids(shape_index, steps, len(keys)),
                              _to_numpy(inner, n).astype(np.int64))
    path = _with_side(path, _to_numpy(back, n).astype(bool))
    return shape_index, _to_numpy(mask, n).astype(np.uint32), path, _to_numpy(normal, n)


def _ids_kernel(scene, sensor, lights, pixel_x, pixel_y, layout):
    """The kernel of :func:`_ids_jit`: (visible-light mask, shape pointers,
    the pointer of the shape inside an instance's group (0 elsewhere), mirror
    chain, shading normal, whether the surface is seen from its back) of each
    pixel's centre ray, every input an argument as :func:`_develop_kernel`'s."""
    _, rule, mirrors, _ = layout
    position = mi.Point2f(pixel_x + 0.5, pixel_y + 0.5)
    ray, _ = _camera_ray(sensor, None, position, 1, centre=True)  # no random numbers
    si, valid, mask, chain = _surface_aovs(scene, ray, lights, rule, mirrors)
    pointers = _hit_shape(si)
    instance = dr.reinterpret_array(mi.UInt32, si.instance)
    inner = dr.select(instance != 0, dr.reinterpret_array(mi.UInt32, si.shape), 0)
    normal = dr.select(valid, si.sh_frame.n, 0.0)
    back = valid & (dr.dot(si.sh_frame.n, ray.d) > 0.0)
    dr.eval(mask, pointers, inner, chain, normal, back)
    return mask, pointers, inner, chain, normal, back


def _ids_scalar(scene, sensor, sampler, pixel_xy, lights, lookup, rule, replay=False):
    """The scalar variant's :func:`_ids_jit`, pixel by pixel."""
    n = len(pixel_xy)
    shape_index = np.zeros(n, dtype=np.int64)
    visible = np.zeros(n, dtype=np.uint32)
    normal = np.zeros((n, 3))
    mirrors = has_mirrors(scene)
    steps = [np.zeros(n, dtype=np.int64) for _ in range(MIRROR_DEPTH if mirrors else 0)]
    inner = np.zeros(n, dtype=np.int64)
    back = np.zeros(n, dtype=bool)
    for k, (x, y) in enumerate(pixel_xy.tolist()):
        ray, _ = _camera_ray(sensor, sampler, mi.Point2f(x + 0.5, y + 0.5), 1, centre=True)
        si, valid, mask, chain = _surface_aovs(scene, ray, lights, rule, mirrors)
        if valid:
            shape_index[k] = lookup.get(id(_hit_shape(si)), 0)
            inner[k] = si.shape.ptr if si.instance is not None else 0
            visible[k] = int(mask)
            normal[k] = np.asarray(si.sh_frame.n, dtype=np.float64)
            back[k] = float(dr.dot(si.sh_frame.n, ray.d)) > 0.0
            for b, (_, shape) in enumerate(chain):
                steps[b][k] = lookup.get(id(shape), 0) if shape is not None else len(lookup) + 1
    path = _with_side(_with_inner_shapes(_path_ids(shape_index, steps, len(lookup)), inner),
                      back)
    return shape_index, visible, path, normal


#: The trace kernels, replayed from a recording when the same trace repeats.
_DEVELOP = Replay(_develop_kernel)
_IDS = Replay(_ids_kernel)
