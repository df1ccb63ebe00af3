"""mitsuba-mrt: the modified ray-tracer (MRT) on Mitsuba 3.

Trace a grid of pixels with any Mitsuba integrator, reconstruct the rest
from scene knowledge: which shape each pixel sees and which lights reach it.

The package is arranged in wings whose imports point one way (see
docs/ARCHITECTURE.md): :mod:`.recon` (numpy stages), :mod:`.modes` (the
reconstruction modes, :func:`reconstruct` and ``auto``'s planner),
:mod:`.renderer` (everything that imports Mitsuba), :mod:`.runtime`
(threads and opt-in process tuning), :mod:`.app` (command line) and
:mod:`.bench` (experiments).

``__all__`` is the user API; the stage types (``SparseTrace``,
``SamplePattern``, ...) are importable from :mod:`.types` and their
modules (and, for now, from here).

Importing the package registers the integrator plugins ``mrt`` and
``matte`` with Mitsuba for the active variant, and again whenever the
variant changes; it changes nothing else in the process.
"""

from __future__ import annotations

from .errors import MRTError, MRTWarning
from .modes import MODES, reconstruct
from .recon.sampling import SamplePattern, grid_pattern
from .types import MRTParams, Reconstruction, Skips, SparseTrace, Timings

__version__ = "0.1.0"

__all__ = ["MODES", "MRTError", "MRTParams", "MRTResult", "MRTWarning", "activate",
           "load_scene", "reconstruct", "register", "render", "render_denoised",
           "render_reference"]


def activate(variant: str = "auto") -> str:
    """Pick a variant (``auto``: LLVM if libLLVM >= 17, else scalar), set it,
    register the plugins and load the renderer's modules."""
    from .renderer.variants import activate as _activate

    chosen = _activate(variant)
    # (here rather than inside the first render, whose time limit counts from the call)
    from .renderer import api  # noqa: F401
    return chosen


def register() -> None:
    """Register the ``mrt`` and ``matte`` plugins for Mitsuba's active variant."""
    from .renderer.variants import register as _register

    _register()


def __getattr__(name):
    # The Mitsuba-facing API is imported on first use, so that the numpy
    # stages work without choosing a variant.
    if name in ("render", "render_reference", "render_denoised", "MRTResult"):
        from .renderer import api

        return getattr(api, name)
    if name == "load_scene":
        from .renderer.scene import load_scene

        return load_scene
    raise AttributeError(f"module 'mitsuba_mrt' has no attribute {name!r}")


def _on_variant_change(*_args) -> None:
    try:
        register()
    except MRTError:
        pass


def _install_variant_hook() -> None:
    try:
        import mitsuba as mi
    except ImportError:  # pragma: no cover - mitsuba is a dependency
        return
    mi.detail.add_variant_callback(_on_variant_change)
    if mi.variant() is not None:
        register()


_install_variant_hook()
