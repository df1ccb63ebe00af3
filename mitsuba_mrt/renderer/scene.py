"""Loading scenes, and reading what an ``mrt`` wrapper in them asks for."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass

import mitsuba as mi

from ..errors import MRTError
from ..types import MRTParams


def load_scene(path: str | os.PathLike, **defines) -> mi.Scene:
    """Load a Mitsuba XML scene, with ``<default>`` parameters overridden.

    Raises MRTError with a one-line message for a missing or malformed file.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise MRTError(f"scene file not found: {path}")
    try:
        return mi.load_file(path, **{k: str(v) for k, v in defines.items()})
    except Exception as exc:  # noqa: BLE001 - Mitsuba raises plain Exceptions
        error = exc
    try:  # name malformed XML as such; Mitsuba's own message is less direct
        ElementTree.parse(path)
    except ElementTree.ParseError as exc:
        raise MRTError(f"malformed XML in {path}: {exc}") from None
    raise MRTError(f"cannot load {path}: {_first_line(error)}") from None


def _first_line(exc: Exception) -> str:
    """The first non-empty line of an exception's message, joined with the next
    when it ends in a colon (Mitsuba puts the detail on the following line);
    an error this package raised inside Mitsuba (a plugin's), as it said it."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    ours = [line for line in lines if "MRTError: " in line]
    if ours:
        return ours[-1].split("MRTError: ", 1)[1]
    if not lines:
        return type(exc).__name__
    if lines[0].endswith(":") and len(lines) > 1:
        return f"{lines[0]} {lines[1]}"
    return lines[0]


def resolve_sensor(scene: mi.Scene, sensor) -> mi.Sensor:
    """``sensor`` itself, or the scene's sensor of that index (checked)."""
    if isinstance(sensor, mi.Sensor):
        return sensor
    sensors = scene.sensors()
    if not 0 <= int(sensor) < len(sensors):
        raise MRTError(f"sensor index {sensor} out of range: the scene has {len(sensors)}")
    return sensors[int(sensor)]


@dataclass
class Wrapper:
    """What an ``mrt`` integrator asks for: the integrator it wraps, its
    parameters and its mode (``None`` for a scene without one)."""

    nested: mi.Integrator
    params: MRTParams | None = None
    mode: str | None = None


def unwrap(scene: mi.Scene, integrator: mi.Integrator | None = None) -> Wrapper:
    """The integrator to trace with, and what an ``mrt`` wrapper around it sets.

    ``integrator`` (default: the scene's own) is an ``mrt`` wrapper when it
    carries ``nested`` and ``params`` (:class:`mitsuba_mrt.renderer.plugins.MRTIntegrator`
    does); anything else is traced as it is.
    """
    integrator = integrator if integrator is not None else scene.integrator()
    params = getattr(integrator, "params", None)
    if isinstance(params, MRTParams) and hasattr(integrator, "nested"):
        return Wrapper(integrator.nested, params, getattr(integrator, "mode", None))
    return Wrapper(integrator)
