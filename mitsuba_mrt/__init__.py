"""mitsuba-mrt: the modified ray-tracer (MRT) on Mitsuba 3.

Trace a grid of pixels with any Mitsuba integrator, reconstruct the rest
from scene knowledge: which shape each pixel sees and which lights reach it.

Importing the package registers the integrator plugins ``mrt`` and
``matte`` for the active Mitsuba variant, and again whenever the variant
changes.  :func:`activate` chooses a variant (LLVM when usable) first.

The reconstruction stages are plain numpy modules: ``sampling``, ``ids``,
``edges``, ``interpolate`` (kernel in ``rbf``), ``compose`` and
``metrics``; the Mitsuba-specific code is in ``trace``, ``plugins``,
``render`` and ``variants``.
"""

from __future__ import annotations

import importlib
import os

# OpenBLAS worker threads spin for about 2**28 cycles (~0.1 s) after each BLAS
# call before they sleep; between the paper mode's factorisations they held
# one of the cores that cdist's threads, the FFTs and Dr.Jit wanted, and the
# mode took ~10 % longer.  2**16 cycles (~20 us) still bridges the pauses
# inside one factorisation.  Read when an OpenBLAS is loaded, so this only
# reaches the BLAS libraries imported after mitsuba_mrt (scipy.linalg's, as a
# rule); a value the user set is kept.
os.environ.setdefault("OPENBLAS_THREAD_TIMEOUT", "16")

from .allocator import keep_freed_memory  # noqa: E402

# Large temporaries are reused instead of being faulted in afresh on every call
# (see mitsuba_mrt.allocator; MITSUBA_MRT_MALLOC=system keeps glibc's defaults).
keep_freed_memory()

from .errors import MRTError
from . import baselines, fast, idpass, refine  # noqa: F401  (register the modes beyond paper)
from .pipeline import MODES, MRTParams, Reconstruction, SparseTrace, reconstruct
from .sampling import SamplePattern, grid_pattern

__version__ = "0.1.0"

__all__ = ["MODES", "MRTError", "MRTParams", "SparseTrace", "Reconstruction", "SamplePattern", "activate",
           "grid_pattern", "load_scene", "reconstruct", "register", "render",
           "render_reference"]


def register() -> None:
    """Register the ``mrt`` and ``matte`` plugins for Mitsuba's active variant."""
    import mitsuba as mi

    if mi.variant() is None:
        raise MRTError("no Mitsuba variant is active: call mi.set_variant(...) "
                       "or mitsuba_mrt.activate() first")
    from . import plugins

    if plugins.VARIANT != mi.variant():
        plugins = importlib.reload(plugins)
    plugins.register_classes()


def activate(variant: str = "auto") -> str:
    """Pick a variant (``auto``: LLVM if libLLVM >= 17, else scalar), set it, register."""
    from .variants import activate as _activate

    return _activate(variant)


def __getattr__(name):
    # The Mitsuba-facing API is imported on first use, so that the numpy
    # stages work without choosing a variant.
    if name in ("render", "render_reference", "load_scene", "MRTResult"):
        from . import api as _api

        return getattr(_api, name)
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
