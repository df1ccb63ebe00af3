"""The ids of traced pixels: what one ray through each pixel's centre meets.

The hit shape (for an instance of a shape group, the instance, and the
shape inside the group), the chain of shapes along the ray's mirror
bounces, which point, spot and directional lights the hit point sees, and the side of
the surface seen; the shape, the chain, the inner shape and the side are
folded into one path id per pixel.  In a JIT variant every centre ray is a
lane of one Dr.Jit wavefront; the scalar variant loops in Python.
"""

from __future__ import annotations

import itertools

import drjit as dr
import mitsuba as mi
import numpy as np

from .develop import MIRROR_DEPTH, _aligned, _camera_ray
from .lanes import _to_numpy, is_jit, logical_not
from .replay import Replay
from .scene_query import _inner_lookup, has_cutouts, has_mirrors

def _is_mirror(bsdf, valid):
    flags = bsdf.flags()
    delta = mi.has_flag(flags, mi.BSDFFlags.Delta)
    smooth = mi.has_flag(flags, mi.BSDFFlags.Smooth)
    if is_jit():
        return valid & delta & ~smooth
    return bool(valid and delta and not smooth)


def _follows(scene) -> bool:
    """Whether a centre ray may go on past its first hit: a mirror or a
    cut-out in ``scene`` (:func:`_follow_mirrors`)."""
    return has_mirrors(scene) or has_cutouts(scene)


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
    """Follow specular bounces from the first hit, and straight on through
    a cut-out's hole: a ``mask`` BSDF whose opacity there is at most a half,
    where one sample at 0.5 takes its null lobe (a leaf's pixels are the
    leaf's, its holes' those of what they show).

    Returns the final (non-mirror) hit, its validity, and per bounce
    (bounced, shape pointer or object).
    """
    ctx = mi.BSDFContext()
    chain = []
    ray = mi.Ray3f(ray)
    for _ in range(MIRROR_DEPTH):
        if not is_jit() and not valid:
            break
        bsdf = si.bsdf(ray)
        bs, _ = bsdf.sample(ctx, si, 0.5, mi.Point2f(0.5, 0.5), valid)
        hole = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Null)
        if is_jit():
            onward = _is_mirror(bsdf, valid) | (valid & hole)
        else:
            onward = _is_mirror(bsdf, valid) or bool(valid and hole)
        if not is_jit() and not onward:
            break
        new_ray = si.spawn_ray(si.to_world(bs.wo))
        new_si = scene.ray_intersect(new_ray, onward)
        if is_jit():
            chain.append((onward, dr.select(onward, _hit_shape(new_si), mi.UInt32(0))))
            ray = dr.select(onward, new_ray, ray)
            si = dr.select(onward, new_si, si)
            valid = dr.select(onward, new_si.is_valid(), valid)
        else:
            chain.append((True, _hit_shape(new_si) if new_si.is_valid() else None))
            ray, si, valid = new_ray, new_si, bool(new_si.is_valid())
    return ray, si, valid, chain


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
        ray, si, valid, chain = _follow_mirrors(scene, ray, si, valid)
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
        lit = valid & logical_not(blocked) & (dr.max(mi.unpolarized_spectrum(spec)) > 0.0)
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


def _with_inner_shapes(path: np.ndarray, inner: np.ndarray, scene) -> np.ndarray:
    """``path`` ids told apart by the shape inside an instance's group.

    An instance is one listed shape, but its group may hold several (a cup
    and the ball in it): where ``inner`` (the address of the shape hit inside
    the group, 0 elsewhere) is set, its number is folded into the path id
    (:func:`_fold`, as :func:`_path_ids` folds long chains).  The numbers
    are the scene's own (:func:`.scene_query._inner_lookup`), so ids agree
    between the traces of a render and between loads of a scene.
    """
    hit = inner != 0
    if not hit.any():
        return path
    addresses, which = np.unique(inner[hit], return_inverse=True)
    lookup = _inner_lookup(scene)
    unlisted = itertools.count(len(lookup) + 1)  # none expected: numbered after the rest
    numbers = np.array([lookup.get(int(a)) or next(unlisted) for a in addresses],
                       dtype=np.int64)
    out = path.copy()
    out[hit] = _fold(path[hit], numbers[which])
    return out


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
    """Shape index, visible-light mask, path id (the shape, its mirror chain
    and side), shading normal and whether the surface is seen from its back,
    of every pixel's centre ray."""
    n = len(pixel_xy)
    layout = (rule, _follows(scene), tuple(int(v) for v in sensor.film().crop_size()))
    mask, pointers, inner, chain, normal, back = _IDS(
        scene, sensor, lights, _aligned(pixel_xy[:, 0]), _aligned(pixel_xy[:, 1]),
        layout, objects=(scene, sensor), record=replay)
    keys = lookup[0]
    shape_index = _to_index(pointers, n, lookup)
    steps = [np.where(_to_numpy(bounced, n).astype(bool),
                      np.where((index := _to_index(ptr, n, lookup)) > 0, index, len(keys) + 1),
                      0)
             for bounced, ptr in chain]
    path = _with_inner_shapes(_path_ids(shape_index, steps, len(keys)),
                              _to_numpy(inner, n).astype(np.int64), scene)
    back = _to_numpy(back, n).astype(bool)
    path = _with_side(path, back)
    return shape_index, _to_numpy(mask, n).astype(np.uint32), path, _to_numpy(normal, n), back


def _to_index(pointers, n: int, lookup: tuple) -> np.ndarray:
    """The 1-based shape index (0: none or unlisted) of each of ``n`` Dr.Jit
    shape pointers, by ``lookup`` (:func:`.scene_query._shape_lookup`)."""
    keys, indices = lookup
    pointers = _to_numpy(pointers, n).astype(np.int64)
    if not len(keys):
        return np.zeros(n, dtype=np.int64)
    pos = np.clip(np.searchsorted(keys, pointers), 0, len(keys) - 1)
    return np.where(keys[pos] == pointers, indices[pos], 0).astype(np.int64)


def shape_indices(scene, sensor, pixel_xy: np.ndarray, lookup, replay: bool) -> np.ndarray:
    """The shape index alone (1-based, 0: none) of each pixel's centre ray,
    as :func:`_ids_jit` gives it, for the cost of one ray a pixel: no lights
    looked at, no mirror followed (``auto``'s textured surfaces)."""
    if not is_jit():
        return _ids_scalar(scene, sensor, None, pixel_xy, [], lookup, "none")[0]
    layout = tuple(int(v) for v in sensor.film().crop_size())
    pointers = _SHAPES(scene, sensor, _aligned(pixel_xy[:, 0]),
                       _aligned(pixel_xy[:, 1]), layout, objects=(scene, sensor),
                       record=replay)
    return _to_index(pointers, len(pixel_xy), lookup)


def _shapes_kernel(scene, sensor, pixel_x, pixel_y, layout):
    """The kernel of :func:`shape_indices`: the pointer of the shape each
    pixel's centre ray hits first (:func:`_hit_shape`)."""
    ray, _ = _camera_ray(sensor, None, mi.Point2f(pixel_x + 0.5, pixel_y + 0.5), 1, centre=True)
    pointers = _hit_shape(scene.ray_intersect(ray))
    dr.eval(pointers)
    return pointers


def _ids_kernel(scene, sensor, lights, pixel_x, pixel_y, layout):
    """The kernel of :func:`_ids_jit`: (visible-light mask, shape pointers,
    the pointer of the shape inside an instance's group (0 elsewhere), mirror
    chain, shading normal, whether the surface is seen from its back) of each
    pixel's centre ray, every input an argument as :func:`.develop._develop_kernel`'s."""
    rule, mirrors, _ = layout
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
    mirrors = _follows(scene)
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
    path = _with_side(_with_inner_shapes(_path_ids(shape_index, steps, len(lookup)), inner,
                                         scene), back)
    return shape_index, visible, path, normal, back


#: The id kernel, replayed from a recording when the same trace repeats.
_IDS = Replay(_ids_kernel)
#: The shapes-only kernel, likewise.
_SHAPES = Replay(_shapes_kernel)
