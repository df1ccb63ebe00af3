"""Choosing and activating a Mitsuba variant.

The LLVM variants need a system libLLVM 17 or newer: with 15 or 16 the JIT
aborts the whole process on its first kernel, which no ``try`` can catch.
So ``auto`` asks Dr.Jit which libLLVM it loaded before it uses one.
"""

from __future__ import annotations

import os
import platform
import sys

from ..errors import MRTError
from ..runtime import jit

VARIANT_CHOICES = ("auto", "scalar_rgb", "llvm_ad_rgb", "cuda_ad_rgb")
LLVM_HINT = ("install libLLVM 17 or newer for the fast LLVM variant "
             "(Debian 12: apt-get install -y libllvm19)")


def choose_variant(requested: str = "auto", warn=None) -> str:
    """Name of the variant to use for ``requested``.

    ``auto`` picks ``llvm_ad_rgb`` when libLLVM >= 17 is loaded, otherwise
    ``scalar_rgb`` with a one-line warning (sent to ``warn``, stderr by
    default).  CUDA is chosen only when asked for.
    """
    if requested not in VARIANT_CHOICES:
        raise MRTError(f"unknown variant {requested!r}; choose one of {', '.join(VARIANT_CHOICES)}")
    if requested == "auto":
        if jit.llvm_usable():
            return "llvm_ad_rgb"
        version = jit.llvm_version()
        found = "no libLLVM" if version is None else "libLLVM " + ".".join(map(str, version))
        (warn or _stderr)(f"warning: {found} found, using the slow scalar_rgb variant; {LLVM_HINT}")
        return "scalar_rgb"
    if requested.startswith("llvm") and not jit.llvm_usable():
        raise MRTError(f"variant {requested} needs libLLVM >= {jit.MIN_LLVM}: {LLVM_HINT}")
    if requested.startswith("cuda") and not jit.cuda_usable():
        raise MRTError(f"variant {requested} needs a CUDA GPU, and none was found")
    return requested


def activate(requested: str = "auto") -> str:
    """Choose a variant, make it Mitsuba's active one and register the plugins."""
    import mitsuba as mi

    variant = choose_variant(requested)
    if variant not in mi.variants():
        raise MRTError(f"this Mitsuba build has no variant {variant}")
    mi.set_variant(variant)
    register()
    return variant


def register() -> None:
    """Register the ``mrt`` and ``matte`` plugins for Mitsuba's active variant.

    The plugin classes derive from the variant's own base classes, so their
    module is reloaded when the variant changed since it was last loaded.
    """
    import importlib

    import mitsuba as mi

    if mi.variant() is None:
        raise MRTError("no Mitsuba variant is active: call mi.set_variant(...) "
                       "or mitsuba_mrt.activate() first")
    from . import plugins

    if plugins.VARIANT != mi.variant():
        plugins = importlib.reload(plugins)
    plugins.register_classes()


def _stderr(message: str) -> None:
    print(message, file=sys.stderr)


def environment(variant: str) -> dict:
    """The variant, versions and machine a result was measured with."""
    import drjit as dr
    import mitsuba as mi

    cpu = platform.processor() or ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return {"variant": variant, "mitsuba": mi.__version__, "drjit": dr.__version__,
            "cpu_count": os.cpu_count(), "cpu_model": cpu or "unknown",
            "machine": platform.machine(), "platform": platform.platform(terse=True),
            "python": platform.python_version()}
