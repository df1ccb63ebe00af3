"""Choosing and activating a Mitsuba variant.

The LLVM variants need a system libLLVM 17 or newer: with 15 or 16 the JIT
aborts the whole process on its first kernel, which no ``try`` can catch.
So ``auto`` asks Dr.Jit which libLLVM it loaded before it uses one.
"""

from __future__ import annotations

import sys

from .errors import MRTError

VARIANT_CHOICES = ("auto", "scalar_rgb", "llvm_ad_rgb", "cuda_ad_rgb")
MIN_LLVM = 17
LLVM_HINT = ("install libLLVM 17 or newer for the fast LLVM variant "
             "(Debian 12: apt-get install -y libllvm19)")


def llvm_version() -> tuple[int, ...] | None:
    """Version of the libLLVM that Dr.Jit loaded, or None when there is none."""
    import drjit as dr

    try:
        version = dr.detail.llvm_version()
    except Exception:  # noqa: BLE001 - any failure means "no usable LLVM"
        return None
    return tuple(version) if version and version[0] > 0 else None


def llvm_usable() -> bool:
    """True when Dr.Jit's LLVM backend can run here without aborting."""
    version = llvm_version()
    return version is not None and version[0] >= MIN_LLVM


def cuda_usable() -> bool:
    """True when Dr.Jit finds a CUDA device."""
    import drjit as dr

    try:
        return bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:  # noqa: BLE001
        return False


def choose_variant(requested: str = "auto", warn=None) -> str:
    """Name of the variant to use for ``requested``.

    ``auto`` picks ``llvm_ad_rgb`` when libLLVM >= 17 is loaded, otherwise
    ``scalar_rgb`` with a one-line warning (sent to ``warn``, stderr by
    default).  CUDA is chosen only when asked for.
    """
    if requested not in VARIANT_CHOICES:
        raise MRTError(f"unknown variant {requested!r}; choose one of {', '.join(VARIANT_CHOICES)}")
    if requested == "auto":
        if llvm_usable():
            return "llvm_ad_rgb"
        version = llvm_version()
        found = "no libLLVM" if version is None else "libLLVM " + ".".join(map(str, version))
        (warn or _stderr)(f"warning: {found} found, using the slow scalar_rgb variant; {LLVM_HINT}")
        return "scalar_rgb"
    if requested.startswith("llvm") and not llvm_usable():
        raise MRTError(f"variant {requested} needs libLLVM >= {MIN_LLVM}: {LLVM_HINT}")
    if requested.startswith("cuda") and not cuda_usable():
        raise MRTError(f"variant {requested} needs a CUDA GPU, and none was found")
    return requested


def activate(requested: str = "auto") -> str:
    """Choose a variant, make it Mitsuba's active one and register the plugins."""
    import mitsuba as mi

    variant = choose_variant(requested)
    if variant not in mi.variants():
        raise MRTError(f"this Mitsuba build has no variant {variant}")
    mi.set_variant(variant)
    from . import register

    register()
    return variant


def _stderr(message: str) -> None:
    print(message, file=sys.stderr)
