"""Denoising with Intel Open Image Denoise (OIDN): the traced grid, or a whole image.

:func:`denoise_grid` is the ``denoise="oidn"`` stage: the grid's pixels
form a small image (grid rows x grid columns), which OIDN's ``RT`` filter
denoises as an HDR image with the trace's albedo and shading normals (those
of the grid pixels themselves) as guides, before the reconstruction.
:func:`denoise_image` is the same filter on any image (the bench's ``oidn``
baseline denoises full renders with it).

OIDN comes from the optional ``pyoidn`` package (``pip install
mitsuba-mrt[denoise]``); without it both raise a one-line :class:`MRTError`.
Its CPU device is created once per process, on first use, and its filters
(one per quality and set of guides) are kept and reused; calls are
serialised by a lock, as one OIDN filter is not reentrant.
"""

from __future__ import annotations

import threading

import numpy as np

from ..errors import MRTError

#: OIDN's quality presets, fastest first.
QUALITIES = ("fast", "balanced", "high")

#: The quality :func:`denoise_grid` uses: on a 2-core CPU ``fast`` takes 0.5 to
#: 0.85 of ``balanced``'s time on the grid of a 400 x 400 image, for an MRT error
#: about 5 % higher; at few spp time buys more (docs/BENCHMARKS.md, Denoising).
GRID_QUALITY = "fast"

MISSING = ('denoise="oidn" needs Intel Open Image Denoise: '
           "pip install mitsuba-mrt[denoise]")

_lock = threading.Lock()
_state: dict = {}  # "device", and (quality, guides, clean_aux) -> its RT filter


def _pyoidn():
    """The pyoidn module, or MRTError naming the extra."""
    try:
        import pyoidn
    except ImportError:
        raise MRTError(MISSING) from None
    except OSError as exc:  # installed, but its native library does not load
        raise MRTError(f"Intel Open Image Denoise does not load: "
                       f"{str(exc).strip().splitlines()[0]}") from None
    return pyoidn


def _check(device, what: str) -> None:
    error = device.get_error()
    if error:
        raise MRTError(f"Open Image Denoise failed ({what}): {str(error).strip().splitlines()[0]}")


def _device(pyoidn):
    """The process's OIDN CPU device (created and committed on first use)."""
    device = _state.get("device")
    if device is None:
        device = pyoidn.Device(pyoidn.OIDN_DEVICE_TYPE_CPU)
        device.commit()
        _check(device, "creating the CPU device")
        _state["device"] = device
    return device


def _filter(pyoidn, device, quality: str, guides: tuple, clean_aux: bool):
    key = (quality, guides, clean_aux)
    flt = _state.get(key)
    if flt is None:
        flt = pyoidn.Filter(device, pyoidn.OIDN_FILTER_TYPE_RT)
        flt.set_bool("hdr", True)
        flt.set_bool("cleanAux", clean_aux)
        flt.set_int("quality", {"fast": pyoidn.OIDN_QUALITY_FAST,
                                "balanced": pyoidn.OIDN_QUALITY_BALANCED,
                                "high": pyoidn.OIDN_QUALITY_HIGH}[quality])
        _check(device, "creating the RT filter")
        _state[key] = flt
    return flt


def _float3(image: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(image, dtype=np.float32)


def denoise_image(color: np.ndarray, albedo: np.ndarray | None = None,
                  normal: np.ndarray | None = None, quality: str = "balanced",
                  clean_aux: bool = False) -> np.ndarray:
    """``color`` (height, width, 3), linear HDR radiance >= 0, denoised by OIDN's RT filter.

    ``albedo`` (in [0, 1]) and ``normal`` (in [-1, 1]), both (height, width, 3),
    are the optional guides (OIDN takes a normal only with an albedo);
    ``clean_aux`` tells OIDN they are noise-free. Returns float64.
    ``quality`` is one of :data:`QUALITIES`.
    """
    pyoidn = _pyoidn()
    if normal is not None and albedo is None:
        normal = None
    images = {"color": _float3(color)}
    if albedo is not None:
        images["albedo"] = _float3(albedo)
    if normal is not None:
        images["normal"] = _float3(normal)
    output = np.empty_like(images["color"])
    with _lock:
        device = _device(pyoidn)
        flt = _filter(pyoidn, device, quality, tuple(images), clean_aux)
        images["output"] = output
        try:
            for name, image in images.items():
                flt.set_image(name, image, pyoidn.OIDN_FORMAT_FLOAT3)
            flt.commit()  # cheap when the sizes are those of the last call
            flt.execute()
            _check(device, "denoising")
        finally:  # the filter holds raw pointers to these arrays: point it away from them
            for name in images:
                flt.unset_image(name)
    return output.astype(np.float64)


def denoise_grid(radiance: np.ndarray, albedo: np.ndarray | None = None,
                 normal: np.ndarray | None = None, denoiser: str = "oidn",
                 quality: str | None = None) -> np.ndarray:
    """The grid image ``radiance`` (rows, columns, 3), denoised with its guides.

    ``albedo`` and ``normal`` are the grid pixels' own (the trace's, 0 where
    the pixel centre sees no surface). Only ``denoiser="oidn"`` exists; the
    public boundary (:class:`~mitsuba_mrt.types.MRTParams`) has checked it.
    ``quality``: default :data:`GRID_QUALITY`.
    """
    return denoise_image(radiance, albedo, normal, quality or GRID_QUALITY)
