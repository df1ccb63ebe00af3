"""The Mitsuba plugins ``matte`` and ``mrt``, and their registration."""

from __future__ import annotations

from dataclasses import fields

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import MRTError
from ..modes import check_controls, check_mode, render_modes
from ..types import MRTParams
from .aovs import AOV_NAMES, aov_images
from .develop import nested_sample
from .lanes import is_jit, logical_not
from .scene_query import has_mirrors

#: The variant whose classes this module defines (it is reloaded on a switch).
VARIANT = mi.variant()


class MatteIntegrator(mi.SamplingIntegrator):
    r"""Deterministic point-light shading, the report's underlying ray-tracer.

    At the first hit, every point and spot light is evaluated with its own
    shadow ray: ``L = sum_lights f(wi, wo) cos(theta) I / d^2``.  With a
    ``diffuse`` BSDF of reflectance ``rho`` and a point light of intensity
    ``pi k`` this is the report's ``rho * k * max(0, n.l) / d^2``.  No
    random numbers are used for diffuse surfaces, so 1 spp is noise-free.
    Perfect mirrors (``conductor``, any purely specular BSDF) are followed
    up to ``max_depth`` bounces.  Area and environment emitters neither
    light the scene nor appear in the image.

    .. pluginparameters::

     * - max_depth
       - |int|
       - Most specular (mirror) bounces followed before shading (Default: 4).
    """

    def __init__(self, props=mi.Properties()):
        super().__init__(props)
        self.max_depth = int(props.get("max_depth", 4))  # mirror bounces followed
        if self.max_depth < 0:
            raise MRTError(f"matte: max_depth must be >= 0, got {self.max_depth}")

    def sample(self, scene, sampler, ray, medium=None, active=True):
        lights = [e for e in scene.emitters()
                  if mi.has_flag(e.flags(), mi.EmitterFlags.DeltaPosition)]
        ctx = mi.BSDFContext()
        ray = mi.Ray3f(ray)
        active = mi.Bool(active)
        result = mi.Spectrum(0.0)
        throughput = mi.Spectrum(1.0)
        first_hit = mi.Bool(False)
        # Without mirrors there is nothing to follow: one hit, a smaller kernel.
        max_depth = self.max_depth if has_mirrors(scene) else 0
        for depth in range(max_depth + 1):
            si = scene.ray_intersect(ray, active)
            valid = active & si.is_valid()
            if depth == 0:
                first_hit = valid
            if not (is_jit() or valid):
                break
            bsdf = si.bsdf(ray)
            flags = bsdf.flags()
            mirror = valid & mi.has_flag(flags, mi.BSDFFlags.Delta) \
                & logical_not(mi.has_flag(flags, mi.BSDFFlags.Smooth))
            shade = valid & logical_not(mirror)
            for light in lights:
                ds, intensity = light.sample_direction(si, mi.Point2f(0.5, 0.5), shade)
                f = bsdf.eval(ctx, si, si.to_local(ds.d), shade)
                lit = shade & logical_not(scene.ray_test(si.spawn_ray_to(ds.p), shade))
                result += dr.select(lit, throughput * f * intensity, 0.0)
            if depth == max_depth or not (is_jit() or mirror):
                break
            bs, weight = bsdf.sample(ctx, si, sampler.next_1d(mirror),
                                     sampler.next_2d(mirror), mirror)
            throughput = dr.select(mirror, throughput * weight, 0.0)
            ray = si.spawn_ray(si.to_world(bs.wo))
            active = mirror & (bs.pdf > 0.0)
        return result, first_hit, []

    def aov_names(self):
        return []

    def to_string(self):
        return f"MatteIntegrator[max_depth={self.max_depth}]"


#: Why ``dr.backward`` or ``dr.forward`` through an ``mrt`` render fails:
#: its image is reconstructed outside Dr.Jit's AD graph (the default of
#: Mitsuba's integrators, naive AD of ``render``, ends in Dr.Jit's "does not
#: depend on the input variable(s)").
NOT_DIFFERENTIABLE = ("mrt: its reconstruction is not differentiable; render with the nested "
                      "integrator (e.g. prb) where gradients are wanted")


def _number(value) -> int:
    """``spp`` or ``seed`` as a Python int: ``mi.render`` passes a Dr.Jit
    array (``mi.UInt32``) where the scene has parameters to differentiate."""
    return int(value[0]) if isinstance(value, dr.ArrayBase) else int(value)


class MRTIntegrator(mi.SamplingIntegrator):
    r"""The modified ray-tracer: trace a grid of pixels, reconstruct the rest.

    Wraps a nested sampling integrator (``matte``, ``direct``, ``path``,
    ``prb``, ...) that renders only the grid-sampled pixels; the other pixels are
    reconstructed per region of equal id (hit shape and visible lights) by
    the report's edge finder and linear-RBF interpolator.  ``mi.render``
    returns R, G, B followed by the AOVs ``id`` (the report's id: shape +
    0.5 per blocked light, under the paper rule), ``shape_index`` (0 =
    background, else 1 + position in the shapes sorted by ``id``), ``visible_lights``
    (bit k = point, spot or directional light k unoccluded) and ``traced`` (1 at traced
    pixels).  Untraced pixels carry their region's ids.  The image has no
    derivatives: ``dr.backward`` through it raises an error.

    .. pluginparameters::

     * - sample_fraction
       - |float|
       - Fraction of the pixels traced, in (0, 1] (Default: 0.1).
     * - filter_sigma
       - |float|
       - Sigma in pixels of the Gaussian id smoothing, in [0, 100] (Default: 1).
     * - filter_cutoff
       - |float|
       - Normalised cutoff of the id smoothing (Default: 0.05).
     * - max_inpoints
       - |int|
       - Most RBF centres per id (Default: 2000).
     * - num_cappoints
       - |int|
       - Brightest and darkest capstone samples per id, each (Default: 10).
     * - id_rule
       - |string|
       - ``paper`` (shape + 0.5 per blocked light), ``exact`` (never collides), or
         ``auto``: paper in mode paper, exact elsewhere (Default: auto).
     * - rbf_degree
       - |int|
       - Polynomial degree added to the RBF: -1 (report), 0 or 1 (Default: -1).
     * - denoise
       - |string|
       - ``oidn``: denoise the traced grid with Intel Open Image Denoise before
         reconstructing it, and ``refine``'s whole image after (needs
         ``pip install mitsuba-mrt[denoise]``) (Default: none).
     * - denoise_quality
       - |string|
       - OIDN's quality with ``denoise`` ``oidn``: ``fast``, or ``balanced`` and ``high``,
         a larger network, slower and usually more accurate; ``auto``: ``high`` on the
         grid, ``fast`` on whole images, but ``auto``'s passes end with ``high`` where
         it pays (Default: auto).
     * - noise_smoothing
       - |float|
       - In ``fast``, ``refine`` and ``idpass``: average each traced grid value with
         the samples of its id nearby that agree with it within this many standard
         deviations of the trace's noise, before interpolating; 0: off (Default: 1.5).
     * - time_limit
       - |float|
       - Mode ``auto``: seconds the whole render may take; the denoised passes
         fill them (Default: none).
     * - noise_threshold
       - |float|
       - Mode ``auto``: the largest estimated relative RMS error accepted; the
         passes end when they meet it (Default: a full render's own noise at the
         scene's spp).
     * - mode
       - |string|
       - ``auto``: the image in denoised passes (box filter, OIDN) until
         ``noise_threshold`` or ``time_limit``; a full render where nothing
         is to gain; or a reconstruction: ``paper``,
         ``fast``, ``refine``, ``idpass``, ``nearest``, ``bicubic`` (Default: auto).
     * - aovs
       - |bool|
       - Append the id AOV channels to the output (Default: true).
     * - (Nested plugin)
       - |integrator|
       - The integrator that traces the sampled pixels (Default: ``path``,
         given any properties the wrapper does not know, e.g. ``max_depth``).
    """

    AOV_NAMES = AOV_NAMES

    def __init__(self, props=mi.Properties()):
        super().__init__(props)
        names = list(props.keys())
        nested = [name for name in names if isinstance(props[name], mi.Integrator)]
        if len(nested) > 1:
            raise MRTError("mrt: expected at most one nested integrator")
        own = {f.name: f for f in fields(MRTParams)}
        unknown = [name for name in names if name not in own and name not in nested
                   and name not in ("mode", "aovs")]
        # The integrator that traces the grid-sampled pixels.
        self.nested = props[nested[0]] if nested else _default_nested(unknown, props)
        if nested and unknown:
            raise MRTError(f"mrt: unknown properties {', '.join(unknown)} (give them to the "
                           f"nested integrator)")
        # Reconstruction parameters, validated once here.
        self.params = MRTParams(**{name: _parameter(name, props[name], f.default)
                                   for name, f in own.items() if name in names})
        # Reconstruction mode (see mitsuba_mrt.renderer.api.render).
        self.mode = check_mode(str(props.get("mode", "auto")), render_modes())
        check_controls(self.mode, self.params)
        # Whether mi.render returns the id AOVs after R, G, B.
        self.output_aovs = bool(props.get("aovs", True))
        # The last MRTResult, for callers who want timings and statistics.
        self.last_result = None

    def render(self, scene, sensor=0, seed=0, spp=0, develop=True, evaluate=True):
        from .api import render
        from .scene import resolve_sensor

        if not develop:
            raise MRTError("mrt: only develop=True is supported")
        result = render(scene, self.nested, sensor=sensor, spp=_number(spp) or None,
                        seed=_number(seed), params=self.params, mode=self.mode)
        self.last_result = result
        aovs = aov_images(result) if self.output_aovs else {}
        return _develop(resolve_sensor(scene, sensor).film(), result.image, result.alpha,
                        [aovs[name] for name in self.aov_names()], self.aov_names())

    def render_forward(self, scene, params, sensor=0, seed=0, spp=0):
        raise MRTError(NOT_DIFFERENTIABLE)

    def render_backward(self, scene, params, grad_in, sensor=0, seed=0, spp=0):
        raise MRTError(NOT_DIFFERENTIABLE)

    def sample(self, scene, sampler, ray, medium=None, active=True):
        # Per-ray queries (e.g. from another integrator) get the nested result.
        return nested_sample(self.nested, scene, sampler, ray, active, medium)

    def aov_names(self):
        return list(self.AOV_NAMES) if self.output_aovs else []

    def to_string(self):
        fields = ", ".join(f"{k}={v}" for k, v in self.params.as_dict().items())
        return f"MRTIntegrator[{fields},\n  nested={self.nested}]"


def _parameter(name: str, value, default):
    """An :class:`MRTParams` field from the XML property ``value``: text for
    the text fields, else a number (a ``<string>`` property read as one), which
    :class:`MRTParams` checks (an ``<integer>`` field given a non-integral
    ``<float>`` is refused there, not truncated)."""
    if isinstance(default, str):
        return str(value)
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            raise MRTError(f"{name} must be a number, got {value!r}") from None
    return value


def _default_nested(names: list, props) -> mi.Integrator:
    """Mitsuba's ``path`` integrator, with the properties the wrapper does not
    know (``max_depth`` ...); an error naming them if ``path`` does not know
    them either."""
    try:
        return mi.load_dict({"type": "path", **{name: props[name] for name in names}})
    except Exception as exc:  # noqa: BLE001 - Mitsuba raises plain Exceptions
        raise MRTError(f"mrt: properties {', '.join(names)} are neither the mrt integrator's "
                       f"nor its default nested path integrator's") from exc


def _develop(film, image: np.ndarray, alpha: np.ndarray | None, aovs: list,
             names: list) -> mi.TensorXf:
    """Put ``image`` (and ``alpha`` for an RGBA film) and ``aovs`` into ``film``
    and develop it, as Mitsuba's own integrators do, so that ``film.bitmap()``
    and ``film.write()`` see the MRT's image; returns the developed tensor
    (R, G, B, [A,] then the AOVs).

    Each pixel is one sample of weight 1 at the pixel's own position, so the
    developed values are the given ones.
    """
    channels = film.prepare(names)
    base = channels - len(names)  # R, G, B, [A,] W
    if base not in (4, 5):
        raise MRTError(f"mrt: a film with {base} base channels is not supported "
                       f"(expected RGB or RGBA)")
    height, width = image.shape[:2]
    ones = np.ones((height, width, 1))
    if alpha is None:
        alpha = ones[..., 0]
    parts = [image] + ([alpha[..., None]] if base == 5 else []) + [ones] \
        + [a[..., None] for a in aovs]
    block = mi.ImageBlock(mi.TensorXf(np.concatenate(parts, axis=-1).astype(np.float32)),
                          offset=film.crop_offset(), rfilter=film.rfilter(), border=False)
    film.put_block(block)
    return film.develop()


def register_classes() -> None:
    """Register this module's ``matte`` and ``mrt`` classes with Mitsuba."""
    mi.register_integrator("matte", lambda props: MatteIntegrator(props))
    mi.register_integrator("mrt", lambda props: MRTIntegrator(props))
