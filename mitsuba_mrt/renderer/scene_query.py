"""What a scene holds, as the trace asks it (Mitsuba-specific).

The scene's shapes in id order and a lookup from the shape a ray hit to its
index; which shapes are mirrors (planar or curved) or purely diffuse, an
``instance`` answering for the shapes of its ``shapegroup``; the point and
spot lights whose visibility the ids track, and whether shadow rays are
needed to find it; whether a trace of the scene can be replayed.  Nothing
here traces a ray: it reads the scene's shapes, BSDFs and emitters.
"""

from __future__ import annotations

import hashlib
import re
from typing import Callable

import drjit as dr
import mitsuba as mi
import numpy as np

from .lanes import is_jit

#: At most this many lights are tracked in the ``visible_lights`` bit mask.
MAX_TRACKED_LIGHTS = 32


def has_mirrors(scene: mi.Scene) -> bool:
    """True if a shape of ``scene`` (one inside a shape group included) has a
    purely specular (delta) BSDF."""
    return any(shows(scene, lambda shape: _is_mirror_bsdf(shape.bsdf()), any))


def has_cutouts(scene: mi.Scene) -> bool:
    """True if a shape of ``scene`` has a BSDF with a null lobe (``mask``, a
    cut-out whose holes show what is behind it; ``null``, which shows it
    everywhere)."""
    return _any_bsdf_with(scene, mi.BSDFFlags.Null)


def has_delta_lobes(scene: mi.Scene) -> bool:
    """True if a shape of ``scene`` has a BSDF that may sample a delta lobe
    (a mirror, glass, a smooth coating): a sample's albedo follows those
    bounces (:func:`~mitsuba_mrt.renderer.develop._albedo_along`)."""
    return _any_bsdf_with(scene, mi.BSDFFlags.Delta)


def transmits(scene: mi.Scene) -> bool:
    """True if a shape of ``scene`` has a BSDF that transmits light (glass, a
    rough or thin dielectric): what is seen through it is an image of the
    scene behind, which no id tells apart."""
    return _any_bsdf_with(scene, mi.BSDFFlags.Transmission)


def _any_bsdf_with(scene: mi.Scene, flag: mi.BSDFFlags) -> bool:
    """True if a shape of ``scene`` has a BSDF with ``flag`` among its lobes' flags."""
    def has(bsdf) -> bool:
        return bsdf is not None and mi.has_flag(int(bsdf.flags()), flag)

    return any(shows(scene, lambda shape: has(shape.bsdf()), any))


def description_key(scene: mi.Scene, sensor: mi.Sensor, integrator: mi.Integrator,
                    pixels: int) -> str:
    """A digest of what a trace of ``pixels`` pixels of ``scene`` through
    ``sensor`` with ``integrator`` is made of (Mitsuba's description of
    each, the variant and Mitsuba's and Dr.Jit's versions): the same in
    every process that loads the same scene with the same parameters, a key
    for what earlier processes measured (:mod:`mitsuba_mrt.runtime.memory`).
    The scene's description is taken as its sorted lines: Mitsuba loads a
    scene's shapes in parallel, and lists them in the order they loaded.
    The samplers' wavefront sizes are left out: every render sets them
    (a process that ran ``mi.render`` describes its sensor otherwise than a
    fresh one)."""
    described = [_described(scene, ordered=True), _described(sensor), _described(integrator)]
    text = "\n".join([mi.variant(), mi.__version__, dr.__version__, *described,
                      str(int(pixels))])
    return hashlib.sha256(text.encode()).hexdigest()[:32]


def _described(obj, ordered: bool = False) -> str:
    """Mitsuba's description of ``obj`` without its samplers' wavefront sizes
    (``wavefront_size``, ``samples_per_wavefront``), its lines sorted where
    ``ordered``."""
    lines = [line for line in str(obj).splitlines() if "wavefront" not in line]
    return "\n".join(sorted(lines) if ordered else lines)


def sampler_bakes_spp(sampler: mi.Sampler) -> bool:
    """Whether ``sampler``'s arithmetic bakes its sample count into the
    kernels (all of Mitsuba's but ``independent``: ``stratified``,
    ``multijitter``, ``orthogonal``, ``ldsampler``): a trace at an spp not
    traced before compiles kernels of its own.  These are also the samplers
    that place a pixel's samples in strata, so that its odd and even samples
    are no independent halves."""
    return not str(sampler).startswith("IndependentSampler")


def set_sample_count(sampler: mi.Sampler, spp: int) -> int:
    """Set ``sampler`` to ``spp`` samples per pixel; return the count it takes
    (``stratified`` and ``multijitter`` round up to a square), without the
    warning Mitsuba logs for the rounding: the callers report the count taken."""
    logger = mi.logger() if hasattr(mi, "logger") else mi.Thread.thread().logger()
    level = logger.log_level()
    logger.set_log_level(mi.LogLevel.Error)
    try:
        sampler.set_sample_count(int(spp))
    finally:
        logger.set_log_level(level)
    return int(sampler.sample_count())


def sample_count_at_most(sampler: mi.Sampler, spp: int) -> int:
    """The largest sample count of at most ``spp`` that ``sampler`` takes as
    it is (``stratified`` rounds others up to a square, ``ldsampler`` to a
    power of four, ``orthogonal`` to a prime's square): a launch planned to
    fit a time traces no more; the least count it takes where none is at
    most ``spp`` (``orthogonal`` and ``ldsampler`` take at least 4).

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> sample_count_at_most(mi.load_dict({"type": "orthogonal"}), 30)
    25
    >>> sample_count_at_most(mi.load_dict({"type": "orthogonal"}), 3)
    4
    """
    trial = sampler.clone()
    count = max(int(spp), 1)
    while count > 1 and set_sample_count(trial, count) > spp:
        count -= 1
    return count if count > 1 else set_sample_count(trial, 1)


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


def emitter_indices(scene: mi.Scene) -> np.ndarray:
    """1-based indices (as in :func:`ordered_shapes`) of the shapes that emit
    light (area lights), which a camera ray may see."""
    return np.flatnonzero([shape.is_emitter() for shape in ordered_shapes(scene)]
                          ).astype(np.int64) + 1


def _is_mirror_bsdf(bsdf) -> bool:
    flags = int(bsdf.flags()) if bsdf is not None else 0
    return mi.has_flag(flags, mi.BSDFFlags.Delta) and not mi.has_flag(flags, mi.BSDFFlags.Smooth)


def replayable(scene: mi.Scene) -> bool:
    """Whether a trace of ``scene`` can be replayed (:mod:`.replay`): not in a
    spectral or polarized variant (their colour tables are not among a
    trace's inputs), not without shapes (Dr.Jit finds no instance for the
    intersection's virtual calls then) and not through a ``batch`` sensor
    (its rays come from a host function, which Dr.Jit cannot record: it
    aborts the process)."""
    return (not (mi.is_spectral or mi.is_polarized) and len(scene.shapes()) > 0
            and not any(s.class_name() == "BatchSensor" for s in scene.sensors()))


def tracked_lights(scene: mi.Scene) -> list:
    """The scene's point, spot and directional lights (:func:`_delta_light`:
    their shadows have sharp edges, which the ids track), at most 32."""
    return [e for e in scene.emitters() if _delta_light(e)][:MAX_TRACKED_LIGHTS]


def shadow_rule(scene: mi.Scene, lights: list) -> str:
    """How light visibility is found: ``rays``, or without shadow rays.

    ``none`` (no tracked light: :func:`tracked_lights`), ``facing`` (a single sphere: a point
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


def _delta_light(emitter) -> bool:
    """Whether ``emitter`` is a point, spot or directional light (one
    position, or one direction: no point or direction of it to sample)."""
    return any(mi.has_flag(emitter.flags(), f)
               for f in (mi.EmitterFlags.DeltaPosition, mi.EmitterFlags.DeltaDirection))


def lit_diffuse_by_points(scene: mi.Scene) -> bool:
    """Whether every surface of ``scene`` is diffuse (:func:`diffuse_shapes`)
    and every emitter a point, spot or directional light: the report's
    scenes, where shading is smooth within a shape and every edge of light
    is a shadow the ids track."""
    emitters = scene.emitters()
    return (len(emitters) > 0 and len(scene.shapes()) > 0
            and all(_delta_light(e) for e in emitters)
            and bool(diffuse_shapes(scene)[1:].all()))


#: Mitsuba's integrators that sample the light of the scene's emitters (their
#: C++ class names, or their Python classes' for those written in Python).
LIGHT_SAMPLING = frozenset({"PathIntegrator", "DirectIntegrator", "VolumetricPathIntegrator",
                            "VolumetricSimplePathIntegrator", "VolumetricMISPathIntegrator",
                            "PRBIntegrator", "PRBVolpathIntegrator"})


def surely_noisy(scene: mi.Scene, integrator: mi.Integrator) -> bool:
    """Whether ``integrator`` samples the light of an emitter of ``scene``
    that is not a point, spot or directional light (an area light, an
    environment): each sample of a pixel it lights draws another point or
    direction of it, so the pixel differs from one set of random numbers to
    another, and no probe is needed to tell the scene is noisy."""
    names = {integrator.class_name(), type(integrator).__name__}
    return bool(names & LIGHT_SAMPLING) and not all(_delta_light(e) for e in scene.emitters())


def environment_map(scene: mi.Scene) -> bool:
    """Whether an environment emitter of ``scene`` varies with direction (an
    ``envmap``, not a ``constant``): its detail, seen or reflected, lies
    inside one region of ids, between the MRT's grid pixels."""
    return any(e.is_environment() and "radiance.value" not in mi.traverse(e).keys()
               for e in scene.emitters())


#: The parameters of a BSDF whose albedo is one colour: a smooth diffuse
#: BSDF's constant reflectance, or that of the one inside a ``twosided``.
_ONE_COLOUR = re.compile(r"(brdf_\d+\.)?reflectance\.value")


def albedo_per_shape(scene: mi.Scene) -> bool:
    """Whether every shape's albedo is one colour, the same for every sample
    that hits it: each BSDF a smooth ``diffuse`` (or a ``twosided`` one) of
    a constant reflectance, whose albedo is that reflectance at every hit.
    A pixel's albedo then needs only a few samples where they all hit one
    surface (:data:`~.develop.ALBEDO_FIRST_SAMPLES`).  Never in a spectral
    variant: there each sample's albedo is that of its own wavelengths."""
    if mi.is_spectral:
        return False

    def one_colour(bsdf) -> bool:
        if bsdf is None or bsdf.class_name() not in ("SmoothDiffuse", "TwoSidedBRDF"):
            return False
        keys = list(mi.traverse(bsdf).keys())
        return bool(keys) and all(_ONE_COLOUR.fullmatch(k) for k in keys)

    return all(shows(scene, lambda shape: one_colour(shape.bsdf()), all))


def shape_albedos(scene: mi.Scene) -> np.ndarray | None:
    """Per shape index (1-based, as in :func:`ordered_shapes`; row 0 for no
    shape) and side (0: the front, 1: the back), the albedo every sample of
    the shape's BSDF gives, (shapes + 1, 2, 3); None unless
    :func:`albedo_per_shape` holds and no shape is an ``instance`` (whose
    group may hold several colours).

    A smooth ``diffuse`` BSDF's sample weight is its reflectance (clipped to
    [0, 1], as the trace clips it) from the front and zero from the back; a
    ``twosided`` one gives its second BSDF's (or its only one's) from the back.
    """
    if not albedo_per_shape(scene):
        return None
    shapes = ordered_shapes(scene)
    if any(shape.class_name() == "Instance" for shape in shapes):
        return None
    table = np.zeros((len(shapes) + 1, 2, 3))

    def colour(params, key) -> np.ndarray:
        value = np.asarray(params[key], dtype=np.float32).ravel()
        return np.clip(np.broadcast_to(value, (3,)), 0.0, 1.0)

    for k, shape in enumerate(shapes, 1):
        params = mi.traverse(shape.bsdf())
        if "reflectance.value" in params:  # one-sided: black from the back
            table[k, 0] = colour(params, "reflectance.value")
        else:
            table[k, 0] = colour(params, "brdf_0.reflectance.value")
            table[k, 1] = colour(params, "brdf_1.reflectance.value"
                                 if "brdf_1.reflectance.value" in params
                                 else "brdf_0.reflectance.value")
    return table


def textured_diffuse_shapes(scene: mi.Scene) -> np.ndarray:
    """:func:`diffuse_shapes`, only those whose reflectance is not one
    colour (a bitmap, a procedural texture, ...): those whose radiance a
    denoiser may be handed as texture times shading."""
    def varies(bsdf) -> bool:
        keys = [k for k in mi.traverse(bsdf).keys() if k.startswith("reflectance.")]
        return bool(keys) and keys != ["reflectance.value"]

    textured = shows(scene, lambda shape: shape.bsdf() is not None and varies(shape.bsdf()))
    return diffuse_shapes(scene) & np.array([False] + textured, dtype=bool)


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
        keys = np.array([_jit_pointer(s) for s in shapes], dtype=np.int64)
        order = np.argsort(keys)
        return keys[order], order + 1
    return {id(s): k + 1 for k, s in enumerate(shapes)}


def _jit_pointer(shape) -> int:
    """``shape``'s Dr.Jit pointer (as ``UInt32``), as a JIT trace reports the shape it hit."""
    return int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(shape))[0])


def _inner_lookup(scene: mi.Scene) -> dict[int, int]:
    """Map from the shapes inside the scene's shape groups to a number each, 1-based.

    The scene does not list these shapes, so they have no index of their
    own.  They are numbered as :func:`ordered_shapes` numbers the listed
    ones, by the natural order of their ids, ties in the order
    :func:`_shape_groups` finds them (group by group, then within a
    group): by what the scene is, not by where its objects live, so each
    load of a scene gives them the same numbers.  Keys are what the id
    trace reports for a hit inside a group: the Dr.Jit pointer (JIT) or
    the address of the C++ object (scalar).
    """
    inner = [shape for _, members in _shape_groups(scene) for shape in members]
    inner = sorted(inner, key=lambda shape: _natural_key(shape.id()))  # stable: ties keep order
    numbers: dict[int, int] = {}
    for shape in inner:
        numbers.setdefault(_jit_pointer(shape) if is_jit() else shape.ptr, len(numbers) + 1)
    return numbers
