"""Loading scenes, and reading what an ``mrt`` wrapper in them asks for."""

from __future__ import annotations

import os
import re
import warnings
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass

import mitsuba as mi
import numpy as np

from ..errors import MRTError, MRTWarning
from ..runtime.allocator import available_memory
from ..types import MRTParams, is_integer

#: Memory a render needs per pixel, roughly: the traced AOVs, the modes' images
#: and temporaries (float64 radiance, ids, masks) and the reference's film.
BYTES_PER_PIXEL = 250


def load_scene(path: str | os.PathLike, **defines) -> mi.Scene:
    """Load a Mitsuba XML scene, with ``<default>`` parameters overridden.

    Raises MRTError with a one-line message for a missing or malformed file,
    for a parameter that sets a sampler's ``sample_count`` below 1
    (:func:`check_sample_counts`: Mitsuba's stratified samplers round it up to
    1 and render anyway), and for a film that is empty or needs more memory
    than is available (:func:`check_film`); warns (:class:`MRTWarning`) about emitters of
    negative intensity (:func:`warn_negative_emitters`).  In the JIT variants
    the scene loads on one thread, so that its kernels are the same in every
    process (and found in Dr.Jit's disk cache).
    """
    path = os.fspath(path)
    if os.path.isdir(path):
        raise MRTError(f"a folder, not a scene file: {path}")
    if not os.path.isfile(path):
        raise MRTError(f"scene file not found: {path}")
    if defines:
        check_sample_counts(path, defines)
    try:
        # one thread in the JIT variants: loaded on several, a scene's kernels
        # come out in one of several variable orders from process to process,
        # and a fresh process may miss Dr.Jit's disk cache (docs/BENCHMARKS.md)
        scene = mi.load_file(path, parallel=mi.variant().startswith("scalar"),
                             **{k: str(v) for k, v in defines.items()})
    except Exception as exc:  # noqa: BLE001 - Mitsuba raises plain Exceptions
        error = exc
    else:
        check_film(scene)
        warn_negative_emitters(scene)
        return scene
    try:  # name malformed XML as such; Mitsuba's own message is less direct
        ElementTree.parse(path)
    except ElementTree.ParseError as exc:
        raise MRTError(f"malformed XML in {path}: {exc}") from None
    raise MRTError(f"cannot load {path}: {_first_line(error)}") from None


def check_sample_counts(path: str, defines: dict) -> None:
    """Raise MRTError where ``defines`` set a ``sample_count`` of the scene
    file at ``path`` (an ``<integer name="sample_count" value="$name"/>``)
    to an integer below 1.  Malformed XML, and values that are no integers,
    are left to the loader, which names them."""
    try:
        root = ElementTree.parse(path).getroot()
    except ElementTree.ParseError:
        return
    for element in root.iter("integer"):
        value = element.get("value", "")
        if element.get("name") != "sample_count" or not value.startswith("$"):
            continue
        name = value[1:]
        if name not in defines:
            continue
        try:
            count = int(str(defines[name]))
        except ValueError:
            continue
        if count < 1:
            raise MRTError(f"{name}={defines[name]} sets the scene's sample_count, "
                           f"which must be >= 1")


def _first_line(exc: Exception) -> str:
    """The first non-empty line of an exception's message; when it ends in a
    colon, joined with the lines that follow (Mitsuba puts the detail there,
    one ``- item`` a line, e.g. the names of unused parameters).  An error this
    package raised inside Mitsuba (a plugin's) is given as it said it."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    ours = [line for line in lines if "MRTError: " in line]
    if ours:
        return ours[-1].split("MRTError: ", 1)[1]
    if not lines:
        return type(exc).__name__
    if lines[0].endswith(":") and len(lines) > 1:
        items = [lines[1]] + [line for line in lines[2:] if line.startswith("-")]
        return f"{lines[0]} " + ", ".join(item.lstrip("- ").strip() for item in items)
    return lines[0]


def check_film(scene: mi.Scene, sensor: int = 0, available: int | None = None) -> None:
    """Refuse, before any work, a film of no pixel or one too large for memory.

    About :data:`BYTES_PER_PIXEL` bytes per pixel are needed; ``available``
    defaults to :func:`available_memory`.
    """
    sensors = scene.sensors()
    if not sensors:
        return
    width, height = (int(v) for v in sensors[min(sensor, len(sensors) - 1)].film().crop_size())
    if width < 1 or height < 1:
        raise MRTError(f"the film is {width} x {height} pixels: width and height must be "
                       f"at least 1 (e.g. -D res=N with N >= 1)")
    needed = BYTES_PER_PIXEL * width * height
    available = available_memory() if available is None else available
    if available is not None and needed > available:
        raise MRTError(f"a {width} x {height} render needs about {_size(needed)} of memory "
                       f"({BYTES_PER_PIXEL} bytes per pixel), more than the "
                       f"{_size(available)} available")


def _size(n: float) -> str:
    for unit in ("bytes", "KB", "MB", "GB", "TB"):
        if n < 1000 or unit == "TB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1000.0


#: The parameters of Mitsuba's emitters that scale their emission.
_EMISSION = ("intensity", "radiance", "irradiance")


def warn_negative_emitters(scene: mi.Scene) -> list[str]:
    """Warn (:class:`MRTWarning`, one line each) about emitters with a negative
    intensity, radiance or irradiance; returns the messages.

    Mitsuba renders them (light is subtracted), which is seldom meant.
    """
    owners = {}
    for shape in scene.shapes():
        emitter = shape.emitter()
        if emitter is not None:
            owners[id(emitter)] = shape.id()
    messages = []
    for position, emitter in enumerate(scene.emitters()):
        params = mi.traverse(emitter)
        for key in params.keys():
            if key.split(".")[0] not in _EMISSION or not key.endswith((".value", ".data")):
                continue
            try:
                least = float(np.min(np.asarray(params[key], dtype=np.float64)))
            except (TypeError, ValueError):
                continue
            if least < 0:
                kind = plugin_name(emitter) or "emitter"
                name = emitter.id() or (f"of shape {owners[id(emitter)]!r}"
                                        if owners.get(id(emitter)) else f"#{position}")
                message = (f"emitter {name} ({kind}) has a negative {key.split('.')[0]} "
                           f"({least:g}): it subtracts light")
                messages.append(message)
                warnings.warn(message, MRTWarning, stacklevel=3)
                break
    return messages


def resolve_sensor(scene: mi.Scene, sensor) -> mi.Sensor:
    """``sensor`` itself, or the scene's sensor of that index (checked), its
    film one the MRT renders (:func:`pixel_format`)."""
    if not isinstance(sensor, mi.Sensor):
        if not is_integer(sensor):
            raise MRTError(f"sensor must be an index or a Mitsuba sensor, got {sensor!r}")
        sensors = scene.sensors()
        if not 0 <= int(sensor) < len(sensors):
            raise MRTError(f"sensor index {sensor} out of range: the scene has {len(sensors)}")
        sensor = sensors[int(sensor)]
    pixel_format(sensor.film())
    return sensor


#: The ``hdrfilm`` pixel formats the MRT renders.  Its images are RGB, with
#: alpha where the film has it; an XYZ film's full render is converted to
#: RGB (:func:`as_rgb`), and the ``mrt`` plugin's RGB image is developed by
#: the film into XYZ, as Mitsuba's own integrators' are.  A luminance film
#: (``y``, ``ya``) only in a monochromatic variant, whose RGB is grey.
PIXEL_FORMATS = ("rgb", "rgba", "xyz", "xyza")


def pixel_format(film: mi.Film) -> str:
    """The pixel format of ``film``, one of :data:`PIXEL_FORMATS` (or ``y``,
    ``ya`` in a monochromatic variant); an MRTError for another (a luminance
    film of a colour variant, whose one channel the MRT's colour
    reconstruction cannot give), or for a film that is not an ``hdrfilm``."""
    text = str(film)
    found = re.search(r"\bpixel_format = (\w+)", text)
    if not text.startswith("HDRFilm") or found is None:
        raise MRTError(f"the film is a {plugin_name(film)}: the MRT renders an hdrfilm's "
                       f"{', '.join(PIXEL_FORMATS)} pixel formats")
    name = found.group(1)
    if name not in PIXEL_FORMATS and not (mi.is_monochromatic and name in ("y", "ya")):
        shown = {"y": "luminance", "ya": "luminance_alpha"}.get(name, name)
        raise MRTError(f"the film's pixel_format is {shown}: the MRT renders colour "
                       f"({', '.join(PIXEL_FORMATS)})")
    return name


def as_rgb(image: np.ndarray, film: mi.Film) -> tuple[np.ndarray, np.ndarray | None]:
    """(RGB, alpha or None) of an image ``film`` developed, (height, width,
    channels), AOVs after its base channels: XYZ converted with Mitsuba's
    own conversion (``mi.xyz_to_srgb``, linear: its matrix), luminance (of a
    monochromatic variant) as grey."""
    name = pixel_format(film)
    colour = 1 if name.startswith("y") else 3
    alpha = image[..., colour] if name.endswith("a") else None
    rgb = np.repeat(image[..., :1], 3, axis=-1) if colour == 1 else image[..., :3]
    if name.startswith("xyz"):
        matrix = np.array([np.array(mi.xyz_to_srgb(mi.ScalarColor3f(*column)), dtype=np.float64)
                           .ravel() for column in np.eye(3)]).T
        rgb = rgb @ matrix.T
    return rgb, alpha


@dataclass
class Wrapper:
    """What an ``mrt`` integrator asks for: the integrator it wraps, its
    parameters and its mode (``None`` for a scene without one)."""

    nested: mi.Integrator
    params: MRTParams | None = None
    mode: str | None = None


def plugin_name(plugin) -> str:
    """The name of ``plugin``'s class (``HDRFilm``, ``MomentIntegrator``,
    ``PRBIntegrator``, ...): Mitsuba's ``class_name()`` of a C++ plugin, the
    Python class's name where that is only the base it derives from.

    Examples
    --------
    >>> plugin_name(mi.load_dict({"type": "ptracer"}))
    'ParticleTracerIntegrator'
    """
    kind = type(plugin)
    name = plugin.class_name() if hasattr(plugin, "class_name") else kind.__name__
    return kind.__name__ if name in {base.__name__ for base in kind.__mro__} else name


def check_traceable(integrator: mi.Integrator, mode: str) -> None:
    """MRTError where ``mode`` traces chosen pixels (every mode but ``auto``,
    which renders such a scene in full) and ``integrator`` is not a sampling
    integrator: ``ptracer`` traces from the lights into the whole image."""
    if mode != "auto" and not isinstance(integrator, mi.SamplingIntegrator):
        raise MRTError(f"mode {mode} traces chosen pixels, which a "
                       f"{plugin_name(integrator)} cannot (mode auto renders it in full)")


#: Of a nested integrator's AOVs, how many the warning of :func:`warn_nested_aovs` names.
NAMED_AOVS = 4


def warn_nested_aovs(integrator: mi.Integrator) -> str | None:
    """Warn (:class:`MRTWarning`, one line) where ``integrator`` has AOVs of
    its own (``aov``, ``moment``): the MRT's image is colour (with alpha)
    and the MRT's id AOVs, reconstructed or, where ``auto`` renders in full,
    taken from ``mi.render``'s, and the integrator's AOVs are not among
    them.  Returns the message (None: no AOVs)."""
    names = list(integrator.aov_names())
    if not names:
        return None
    # the user's names first (``_arg_N.*`` are channels Mitsuba names after nested plugins)
    names.sort(key=lambda name: name.startswith("_arg_"))
    shown = ", ".join(names[:NAMED_AOVS]) + (", ..." if len(names) > NAMED_AOVS else "")
    message = (f"the {plugin_name(integrator)}'s {len(names)} AOV channels ({shown}) are not "
               f"in the MRT's output, only colour and the MRT's ids: mi.render with it gives "
               f"them")
    warnings.warn(message, MRTWarning, stacklevel=3)
    return message


def unwrap(scene: mi.Scene, integrator: mi.Integrator | None = None) -> Wrapper:
    """The integrator to trace with, and what an ``mrt`` wrapper around it sets.

    ``integrator`` (default: the scene's own) is an ``mrt`` wrapper when it
    carries ``nested`` and ``params`` (:class:`mitsuba_mrt.renderer.plugins.MRTIntegrator`
    does); any other integrator is traced as it is; no integrator, or
    something else, is an MRTError, as is a ``scene`` that is not a scene.
    """
    if not isinstance(scene, mi.Scene):
        raise MRTError(f"scene must be a Mitsuba scene (mitsuba_mrt.load_scene loads a file), "
                       f"got {scene!r}")
    integrator = integrator if integrator is not None else scene.integrator()
    if integrator is None:
        raise MRTError("the scene has no integrator: add one to it (in Python, or pass "
                       "integrator=)")
    if not isinstance(integrator, mi.Integrator):
        raise MRTError(f"integrator must be a Mitsuba integrator, got {integrator!r}")
    params = getattr(integrator, "params", None)
    if isinstance(params, MRTParams) and hasattr(integrator, "nested"):
        return Wrapper(integrator.nested, params, getattr(integrator, "mode", None))
    return Wrapper(integrator)
