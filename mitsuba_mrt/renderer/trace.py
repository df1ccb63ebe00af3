"""Stage 2: tracing only the sampled pixels, with their ids (Mitsuba-specific).

:func:`trace_pixels` is the stage's one entry point: it traces the
samples of the given pixels and develops them (:mod:`.develop`: radiance,
alpha, variance, albedo and normal), traces one ray through each pixel's
centre for the ids (:mod:`.ids`: shape, mirror chain, visible lights), and
asks the scene what it holds (:mod:`.scene_query`: its lights, its
mirrors); the kernels are replayed where a trace repeats (:mod:`.replay`).
"""

from __future__ import annotations

import time

import mitsuba as mi
import numpy as np

from ..errors import MRTError
from ..types import SparseTrace
from .albedo_pass import albedo_pass
from .develop import (ALBEDO_FIRST_SAMPLES, _develop_jit, _develop_scalar, _Developed,
                      any_recorded, every_pixel_recorded)
from .ids import _ids_jit, _ids_scalar, shape_indices
from .lanes import is_jit
from .replay import active as replay_active
from .replay import padded_size
from .pixel_filter import filter_reach
from .scene import plugin_name
from .scene_query import (_shape_lookup, albedo_per_shape, curved_mirror_indices,
                          emitter_indices, replayable, set_sample_count, shadow_rule,
                          shape_albedos, tracked_lights)

#: Albedo (per channel) below which a pixel is not demodulated: dividing by
#: it would turn the noise of a nearly black surface into huge values.  Dark
#: textures go far lower (black in an sRGB PNG is about 0.003 linear), and
#: their pixels must be demodulated like their bright neighbours.
ALBEDO_MIN = 0.001

#: Added to a trace's seed for the albedo of the pixels whose first samples
#: disagreed on it (:func:`trace_pixels`): numbers no other trace draws.
RETRACE_SEED = 0x9E3779B9


def trace_pixels(scene: mi.Scene, sensor: mi.Sensor, integrator: mi.Integrator,
                 pixel_xy: np.ndarray, spp: int, seed: int = 0, aovs: bool = True,
                 radiance: bool = True, replay: bool = False,
                 pad: bool = False, box: bool = False, ids: bool = True,
                 albedo: bool = True, halves: bool = False,
                 variance: bool = True) -> SparseTrace:
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
    albedo : bool
        With ``aovs``: also the samples' albedo (without ``radiance``: the id
        pass's); without, it is zero and the samples cost what the
        integrator's alone do (for pixels whose ids alone are used:
        ``refine``'s edges, ``auto``'s textured surfaces).
    halves : bool
        Also the mean radiance of each pixel's odd-numbered samples
        (``odd``): with the even-numbered ones, two estimates of the pixel
        from one launch (independent for the ``independent`` sampler).
    variance : bool
        Also each pixel's sample variance (``variance``; None without it,
        where no stage reads it).
    """
    if not isinstance(integrator, mi.SamplingIntegrator):
        raise MRTError(f"the nested integrator must be a sampling integrator, got a "
                       f"{plugin_name(integrator)}")
    if int(spp) < 1:  # a kernel would divide by it: the process dies of SIGFPE
        raise MRTError(f"spp must be >= 1, got {spp}")
    pixel_xy = np.asarray(pixel_xy, dtype=np.int64)
    n = len(pixel_xy)
    if n == 0 and is_jit():  # Dr.Jit aborts the process on a launch of no lanes
        return trace_pixels(scene, sensor, integrator, np.zeros((1, 2), np.int64), spp, seed,
                            aovs, radiance, box=box, ids=ids, albedo=albedo,
                            halves=halves, variance=variance).take(slice(0, 0))
    if pad and n and is_jit() and replay_active() and replayable(scene):
        return trace_pixels(scene, sensor, integrator, _padded(pixel_xy), spp, seed, aovs,
                            radiance, replay=True, box=box, ids=ids, albedo=albedo,
                            halves=halves, variance=variance).take(slice(0, n))
    start = time.perf_counter()
    lights = tracked_lights(scene)
    rule = shadow_rule(scene, lights)
    sampler = sensor.sampler().clone()
    spp = set_sample_count(sampler, spp)
    replay = replay and is_jit() and replayable(scene)
    zero = np.zeros(n, np.int64)
    develop = _develop_jit if is_jit() else _develop_scalar
    one_colour = aovs and albedo_per_shape(scene)
    if radiance:
        samples = _samples(develop, scene, sensor, integrator, sampler, pixel_xy, spp, seed,
                           aovs and albedo, replay, box, halves, ids, one_colour, variance)
    shape_index, visible, path_id, normal = zero, np.zeros(n, np.uint32), zero, None
    if aovs and ids:
        shape_index, visible, path_id, normal, back = (_ids_jit if is_jit() else _ids_scalar)(
            scene, sensor, sampler, pixel_xy, lights, _shape_lookup(scene), rule, replay)
    if aovs and not radiance and albedo:  # the id pass: albedo alone
        table = shape_albedos(scene) if ids and one_colour else None
        samples = albedo_pass(develop, scene, sensor, sampler, pixel_xy, seed, replay, box,
                              (shape_index, path_id) if ids else None,
                              None if table is None else table[shape_index, back.astype(np.int64)])
    elif aovs and not radiance:  # the ids alone
        samples = _Developed(np.zeros((n, 3)), np.zeros(n), np.zeros((n, 3)), np.zeros((n, 3)),
                             normal)
    if aovs and not ids:
        normal = samples.normal
    if not (radiance or aovs):
        samples = _Developed(np.zeros((n, 3)), np.zeros(n), np.zeros((n, 3)), np.zeros((n, 3)))
    if aovs and ids:  # only a surface seen at the pixel's centre is demodulated
        samples.albedo[shape_index == 0] = 0.0
    if aovs:  # and not a black one
        samples.albedo[samples.albedo < ALBEDO_MIN] = 0.0
    curved = curved_mirror_indices(scene) if aovs and ids else np.zeros(0, np.int64)
    lit = emitter_indices(scene) if aovs and ids else np.zeros(0, np.int64)
    return SparseTrace(samples.radiance if radiance else np.zeros((n, 3)),
                       samples.albedo if aovs else np.zeros((n, 3)), shape_index, visible,
                       len(lights), spp, time.perf_counter() - start,
                       shadow_rays=rule == "rays", path_id=path_id,
                       curved_mirror=np.isin(shape_index, curved) if len(curved) else None,
                       alpha=samples.alpha if radiance else None,
                       variance=samples.variance if radiance and variance else None,
                       normal=normal,
                       odd=samples.odd if radiance else None, albedo_per_shape=one_colour,
                       emitter=np.isin(shape_index, lit) if len(lit) else None,
                       filter_reach=0 if box else filter_reach(sensor.film().rfilter().radius()))


def pass_recorded(scene: mi.Scene, sensor: mi.Sensor, integrator: mi.Integrator, spp: int,
                  albedo: bool = True, halves: bool = False) -> bool:
    """Whether :func:`trace_pixels` of every pixel at ``spp`` (``box``,
    no ids, ``replay``; ``aovs`` and ``albedo`` as ``albedo``, ``halves``)
    would replay a recording: one such trace ran before in this process, so
    its kernels are compiled (a sampler that bakes its spp into them
    compiles them anew at a new spp)."""
    if not (is_jit() and replayable(scene)):  # (whether replays are on: the table's to say)
        return False
    taken = set_sample_count(sensor.sampler().clone(), spp)
    return every_pixel_recorded(scene, sensor, integrator, taken, albedo, halves)


def scene_warm(scene: mi.Scene, sensor: mi.Sensor, integrator: mi.Integrator) -> bool:
    """Whether a trace of ``scene`` through ``sensor`` with ``integrator``
    finds its first uses paid: in a JIT variant, where this process recorded
    one (:func:`trace_pixels` with ``replay``; a fresh process's first trace
    of the scene records its kernels and pays its first uses); always in a
    scalar variant, which records nothing."""
    return not is_jit() or any_recorded(scene, sensor, integrator)


def trace_shapes(scene: mi.Scene, sensor: mi.Sensor, pixel_xy: np.ndarray,
                 replay: bool = False) -> np.ndarray:
    """The shape index (1-based, 0: none) of what one ray through each of
    ``pixel_xy``'s centres hits: the ids' shape alone, for one ray a pixel
    (no light looked at, no mirror followed; ``replay`` as
    :func:`trace_pixels`')."""
    pixel_xy = np.asarray(pixel_xy, dtype=np.int64)
    return shape_indices(scene, sensor, pixel_xy, _shape_lookup(scene),
                         replay and is_jit() and replayable(scene))


def _samples(develop, scene, sensor, integrator, sampler, pixel_xy: np.ndarray, spp: int,
             seed: int, albedo: bool, replay: bool, box: bool, halves: bool,
             ids: bool, one_colour: bool, variance: bool = True) -> _Developed:
    """The developed samples of ``pixel_xy``, their albedo (with ``albedo``)
    from as few samples as it needs: where every shape's albedo is one colour
    (``one_colour``: :func:`.scene_query.albedo_per_shape`) and the ids give
    the normal, from each pixel's first :data:`~.develop.ALBEDO_FIRST_SAMPLES`;
    where those disagree (an edge), from an albedo trace of the pixel's own,
    as many samples on a seed of their own."""
    few = (ALBEDO_FIRST_SAMPLES if one_colour and albedo and ids and not halves and is_jit()
           else 0)
    samples = develop(scene, sensor, integrator, sampler, pixel_xy, spp, seed, albedo,
                      replay, box, halves=halves, normals=not ids, albedo_samples=few,
                      variance=variance)
    if spp <= few or samples.albedo_varies is None or not samples.albedo_varies.any():
        return samples  # (every sample traced its albedo, or they all agreed)
    again = np.flatnonzero(samples.albedo_varies)
    xy = _padded(pixel_xy[again]) if replay and replay_active() else pixel_xy[again]
    samples.albedo[again] = develop(scene, sensor, None, sampler, xy, spp,
                                    (seed + RETRACE_SEED) & 0xFFFFFFFF, True, replay, box,
                                    normals=False).albedo[:len(again)]
    return samples


def _padded(pixel_xy: np.ndarray) -> np.ndarray:
    """``pixel_xy`` followed by copies of its first pixel up to
    :func:`.replay.padded_size`: a set whose size changes from render to
    render, traced at one of a few sizes that are recorded once."""
    extra = padded_size(len(pixel_xy)) - len(pixel_xy)
    return np.concatenate([pixel_xy, np.repeat(pixel_xy[:1], extra, axis=0)])
