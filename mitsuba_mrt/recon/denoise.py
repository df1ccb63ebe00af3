"""Denoising with Intel Open Image Denoise (OIDN): the traced grid, or a whole image.

:func:`denoise_grid` is the ``denoise="oidn"`` stage: the grid's pixels
form a small image (grid rows x grid columns), which OIDN's ``RT`` filter
denoises as an HDR image with the trace's albedo and shading normals (those
of the grid pixels themselves) as guides, before the reconstruction.  On a
textured diffuse surface (:func:`textured_pixels`) it denoises the shading
instead, the radiance divided by the albedo, and multiplies the albedo back.
:func:`denoise_image` is the same filter on any image (the bench's ``oidn``
baseline denoises full renders with it).

OIDN comes from the optional ``mitsuba-oidn`` package (``pip install
mitsuba-mrt[denoise]``), which runs OIDN on Dr.Jit's own worker threads;
without it both raise a one-line :class:`MRTError`.  Its CPU device is
created once per process, on first use, and its filters (one per quality,
set of guides and image size, the last :data:`FILTERS_KEPT`) are kept
committed and reused; calls are serialised by a lock, as one OIDN filter
is not reentrant.
"""

from __future__ import annotations

import atexit
import contextlib
import threading
import time
from collections import OrderedDict

import numpy as np

from ..errors import MRTError
from ..runtime import memory
from ..runtime.recent import note, typical
from .compose import safe_albedo

#: OIDN's quality presets, fastest first.
QUALITIES = ("fast", "balanced", "high")


def preset(quality: str, auto: str = "fast") -> str:
    """OIDN's preset for a ``denoise_quality`` setting: ``auto`` is ``auto``'s
    preset, by default a whole image's, ``fast`` (``auto``'s passes choose
    their last call's preset themselves; the MRT's grid takes
    :func:`grid_preset`'s).

    Examples
    --------
    >>> preset("auto"), preset("high"), preset("auto", auto="high")
    ('fast', 'high', 'high')
    """
    return auto if quality == "auto" else quality


#: The preset the MRT's grid is denoised at where ``denoise_quality`` is
#: ``auto`` (:func:`grid_preset`), and :func:`denoise_grid`'s default: the grid
#: holds a tenth to a third of the pixels, so that ``high``'s call is a small
#: share of an MRT render's time, for a lower error than ``fast``'s on every
#: scene and mode ``auto`` takes the MRT on (``examples/grid_preset.py``).
GRID_QUALITY = "high"


def grid_preset(quality: str) -> str:
    """OIDN's preset for the MRT's grid at a ``denoise_quality`` setting:
    ``auto`` is :data:`GRID_QUALITY` (whole images, :func:`preset`, take
    ``fast``).

    Examples
    --------
    >>> grid_preset("auto"), grid_preset("fast")
    ('high', 'fast')
    """
    return preset(quality, GRID_QUALITY)

#: Committed filters kept (a render alternates a few image sizes: the grid,
#: ``auto``'s estimate rows and the whole image; a new size costs a commit).
FILTERS_KEPT = 4

#: A diffuse surface is textured where its grid pixels' albedo (mean over
#: RGB) spans more than this ratio, 95th over 5th percentile: the pixels of a
#: single colour differ only where they straddle another shape.
TEXTURE_CONTRAST = 1.5
#: Fewest grid pixels of a surface for its albedo's spread to say anything.
TEXTURE_MIN_PIXELS = 8

MISSING = ('denoise="oidn" needs Intel Open Image Denoise: '
           "pip install mitsuba-mrt[denoise]")

_lock = threading.Lock()
# "device"; "filters": (quality, guides, clean_aux, shape) -> RT filter;
# "recent": quality -> {pixels: seconds of the last RECENT_CALLS calls at that
# size, each its filter's set-up left out}; "first calls": (quality, pixels) ->
# what earlier processes' first calls took (runtime.memory), read once
_state: dict = {}
# (non-empty once release() is registered to run when Python exits)
_released_at_exit: list = []
# whether OIDN counts as not installed: the innermost hidden() block's
_hidden = [False]


def _oidn():
    """The mitsuba_oidn module, or MRTError naming the extra (also within
    :func:`hidden`)."""
    if _hidden[-1]:
        raise MRTError(MISSING)
    try:
        import mitsuba_oidn
    except ImportError:
        raise MRTError(MISSING) from None
    except OSError as exc:  # installed, but its native library does not load
        raise MRTError(f"Intel Open Image Denoise does not load: "
                       f"{str(exc).strip().splitlines()[0]}") from None
    return mitsuba_oidn


def oidn_available() -> bool:
    """Whether Intel Open Image Denoise can be used (``mitsuba_oidn`` imports and loads)."""
    try:
        _oidn()
    except MRTError:
        return False
    return True


@contextlib.contextmanager
def hidden(enabled: bool = True):
    """Within the block (where ``enabled``), OIDN counts as not installed:
    :func:`oidn_available` is False and every call raises the missing
    extra's :class:`MRTError`, as in a process without ``mitsuba-oidn``
    (``bench rival --no-oidn`` measures ``auto`` so).

    Examples
    --------
    >>> with hidden():
    ...     oidn_available()
    False
    """
    _hidden.append(bool(enabled))
    try:
        yield
    finally:
        _hidden.pop()


def release() -> None:
    """Let go of the OIDN device and filters; the next call creates them anew."""
    with _lock:
        _state.clear()


def denoise_seconds(pixels: int, quality: str) -> float | None:
    """The seconds :func:`denoise_image` (or :func:`denoise_shading`) is
    expected to take on ``pixels`` pixels at ``quality``, its filter's
    set-up left out (None before any call at ``quality`` in this process):
    the recent calls' on that many pixels (:data:`RECENT_CALLS`);
    else a line through the last calls' times on the two largest images (a
    fixed cost and one per pixel), or the one image's time scaled to
    ``pixels``."""
    table = {size: typical(calls)
             for size, calls in _state.get("recent", {}).get(quality, {}).items()}
    if not table:
        return None
    if pixels in table:
        return table[pixels]
    sizes = sorted(table)[-2:]
    largest = sizes[-1]
    if len(sizes) == 2:
        slope = (table[sizes[1]] - table[sizes[0]]) / (sizes[1] - sizes[0])
        if slope > 0:
            return max(table[largest] + slope * (pixels - largest), 0.0)
    return table[largest] * pixels / largest


#: Seconds a call of :func:`denoise_image` takes per pixel and worker thread,
#: with both guides, before any call in the process has measured it: a warm
#: call's on a 2-core x86 CPU (32-512 px a side); and the part of a process's
#: first call that does not grow with the pixels (OIDN's import, its device,
#: the filter's weights), which makes a small image's first call 2-5 times a
#: warm one and a large image's 1.2-1.35 times.  With
#: :data:`FIRST_CALL_SHARE` on both, a first call takes 0.48-0.89 of what
#: they say on the Intel VM of docs/BENCHMARKS.md (fresh processes, 32-512
#: px), so that a first time-limited render plans for a call no faster than
#: it will be; on the slower AMD one 1.5-2.5 (``examples/first_calls.py``).
PRIOR_SECONDS = {"fast": 0.95e-6, "balanced": 1.8e-6, "high": 1.8e-6}
PRIOR_FIXED = {"fast": 0.006, "balanced": 0.01, "high": 0.01}
#: The first call on an image size at a preset takes this share longer than
#: the next ones (OIDN makes that filter's buffers as it runs): 0.25-0.35 on
#: 2 cores at 256-512 px.
FIRST_CALL_SHARE = 0.35


def calls_at(quality: str) -> int:
    """How many calls at ``quality`` this process has timed, up to
    :data:`RECENT_CALLS` per image size (1: the first, which set OIDN up)."""
    return sum(len(calls) for calls in _state.get("recent", {}).get(quality, {}).values())


def expected_seconds(pixels: int, quality: str) -> float:
    """What the next call on ``pixels`` pixels at ``quality`` is expected to
    take: the recent calls' on that many pixels; else :func:`denoise_seconds`
    (from other sizes), or before any call at ``quality`` in this process
    :data:`PRIOR_FIXED` and :data:`PRIOR_SECONDS`' for ``pixels`` on Dr.Jit's
    worker threads (OIDN's threads here), :data:`FIRST_CALL_SHARE` longer."""
    seconds = denoise_seconds(pixels, quality)
    if pixels in _state.get("recent", {}).get(quality, {}):
        return seconds
    if seconds is None:
        return prior_seconds(pixels, quality)
    return seconds * (1.0 + FIRST_CALL_SHARE)


def prior_seconds(pixels: int, quality: str) -> float:
    """What a process's first call on ``pixels`` pixels at ``quality`` is
    expected to take before any call has measured one: :data:`PRIOR_FIXED`
    and :data:`PRIOR_SECONDS`' for ``pixels`` on Dr.Jit's worker threads
    (OIDN's threads here), :data:`FIRST_CALL_SHARE` longer; or where less,
    the longest of the last earlier processes' first calls, where they are
    remembered (:mod:`mitsuba_mrt.runtime.memory`): a first call that was
    slower (a small image's set-up, the machine's noise) does not make a
    plan more cautious than the prior's."""
    import drjit as dr

    seconds = PRIOR_FIXED[quality] + PRIOR_SECONDS[quality] * pixels / max(
        int(dr.thread_count()), 1)
    prior = seconds * (1.0 + FIRST_CALL_SHARE)
    remembered = _remembered_first_call(quality, int(pixels))
    return prior if remembered is None else min(remembered, prior)


def _device(oidn):
    """The process's OIDN CPU device (created and committed on first use;
    it and the filters are let go when Python exits, before the extension
    is: nanobind reports OIDN objects still alive then as leaks)."""
    device = _state.get("device")
    if device is None:
        device = oidn.Device(oidn.DeviceType.CPU)
        device.commit()
        _state["device"] = device
        if not _released_at_exit:
            atexit.register(release)
            _released_at_exit.append(True)
    return device


def _filter(oidn, device, quality: str, guides: tuple, clean_aux: bool, shape: tuple):
    """The RT filter for these settings and image size (the least recently
    used goes), and whether it was made here."""
    filters = _state.setdefault("filters", OrderedDict())
    key = (quality, guides, clean_aux, shape)
    flt = filters.get(key)
    made = flt is None
    if made:
        flt = device.new_filter("RT")
        flt.hdr = True
        flt.clean_aux = clean_aux
        flt.quality = {"fast": oidn.Quality.Fast, "balanced": oidn.Quality.Balanced,
                       "high": oidn.Quality.High}[quality]
        filters[key] = flt
        while len(filters) > FILTERS_KEPT:
            filters.popitem(last=False)
    filters.move_to_end(key)
    return flt, made


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
    start = time.perf_counter()
    output, setup, first = _run_filter(color, albedo, normal, quality, clean_aux)
    _record(quality, output.shape[:2], time.perf_counter() - start, setup, first)
    return output


def _run_filter(color, albedo, normal, quality: str,
                clean_aux: bool) -> tuple[np.ndarray, float, bool]:
    """:func:`denoise_image`'s work: (the float64 output, the seconds of its
    filter's set-up, whether this was the filter's first call)."""
    oidn = _oidn()
    if normal is not None and albedo is None:
        normal = None
    images = {"color": _float3(color)}
    if albedo is not None:
        images["albedo"] = _float3(albedo)
    if normal is not None:
        images["normal"] = _float3(normal)
    output = np.empty_like(images["color"])
    with _lock:
        try:
            device = _device(oidn)
            flt, first = _filter(oidn, device, quality, tuple(images), clean_aux, output.shape)
            images["output"] = output
            try:
                for name, image in images.items():
                    flt.set_image(name, image)
                begin = time.perf_counter()
                flt.commit()  # (a new filter's set-up: not part of a call's expected time)
                setup = time.perf_counter() - begin
                flt.execute()
            finally:  # the filter holds raw pointers to these arrays: point it away from them
                for name in images:
                    flt.unset_image(name)
        except oidn.Error as exc:
            raise MRTError(f"Open Image Denoise failed: "
                           f"{str(exc).strip().splitlines()[0]}") from None
    return output.astype(np.float64), setup, first


#: A size's expected time is the median of its last this many calls (the
#: lower of two): one slow call (the machine's noise) would otherwise make
#: a time-limited render take a preview, whose OIDN call is on its grid
#: alone, so that no later call on the whole image measured it again.
RECENT_CALLS = 3


def _record(quality: str, shape: tuple, total: float, setup: float = 0.0,
            first: bool = False) -> None:
    """Note what a call on an image of ``shape`` at ``quality`` took
    (``total`` seconds, of which its filter's ``setup``):
    :func:`denoise_seconds`, the median of the last :data:`RECENT_CALLS`,
    without the set-up; a filter's ``first`` call as what a later one is
    expected to take, less :data:`FIRST_CALL_SHARE` (it made the filter's
    buffers).  A process's first call at ``quality`` is remembered whole
    for later processes' (:func:`prior_seconds`)."""
    recent = _state.setdefault("recent", {})
    if quality not in recent:
        _remember_first_call(quality, shape[0] * shape[1], total)
    seconds = total - setup
    if first:
        seconds /= 1.0 + FIRST_CALL_SHARE
    note(recent.setdefault(quality, {}).setdefault(shape[0] * shape[1], []), seconds,
         RECENT_CALLS)


def _first_call_key(quality: str, pixels: int) -> str:
    return f"oidn/{quality}/{int(pixels)}"


def _remembered_calls(quality: str, pixels: int) -> list:
    """Earlier processes' first calls at ``quality`` on ``pixels`` pixels, as
    the memory (:mod:`mitsuba_mrt.runtime.memory`) keeps them; [] where none
    are, or the memory is off."""
    value = memory.recall(_first_call_key(quality, pixels)) or {}
    return [float(v) for v in value.get("seconds", []) if isinstance(v, (int, float)) and v > 0]


def _remember_first_call(quality: str, pixels: int, seconds: float) -> None:
    """Keep ``seconds``, a process's first call at ``quality`` on ``pixels``
    pixels, with the last earlier ones (:data:`RECENT_CALLS`) in the memory of
    earlier processes."""
    calls = _remembered_calls(quality, pixels)
    note(calls, seconds, RECENT_CALLS)
    memory.remember(_first_call_key(quality, pixels), {"seconds": calls})


def _remembered_first_call(quality: str, pixels: int) -> float | None:
    """The longest of earlier processes' first calls at ``quality`` on
    ``pixels`` pixels (:func:`_remember_first_call`), read once per process;
    None where none is remembered."""
    known = _state.setdefault("first calls", {})
    if (quality, pixels) not in known:
        known[quality, pixels] = max(_remembered_calls(quality, pixels), default=None)
    return known[quality, pixels]


#: At most this many samples per pixel, a render that denoises textures as
#: their shading multiplies it back by the albedo denoised too
#: (:func:`denoise_shading`'s ``clean_texture``): on the five textured
#: gallery scenes at 256 px, 1 spp had 1-13 % less error than with the
#: samples' own albedo, 2 spp 0.5-4 %, 4 spp 0-1.5 % (less than the extra
#: OIDN call costs), 8 spp up to 1 % more (``python examples/texture_noise.py``).
CLEAN_TEXTURE_SPP = 2
#: The preset of that call.
TEXTURE_QUALITY = "fast"


def denoise_shading(color: np.ndarray, albedo: np.ndarray, normal: np.ndarray | None,
                    textured: np.ndarray, quality: str, clean_texture: bool = False) -> np.ndarray:
    """``color`` (height, width, 3) denoised by OIDN in one call, the pixels
    marked ``textured`` (height, width) as their shading: divided by their
    ``albedo`` (that of the same samples as ``color``: another sample set's
    would leave their difference in the texture), with a flat albedo guide
    there, and multiplied back after.

    A textured diffuse surface's radiance is its texture times a smooth
    shading; OIDN keeps a texture it is shown as a guide only as well as its
    network can, and the division hands it the smooth part alone.  With
    ``clean_texture`` the shading is multiplied back by the albedo denoised
    too (a second call, OIDN on the albedo alone, as its documentation
    cleans a noisy guide): a pixel's albedo is the mean of its samples'
    texels, and of a texture finer than a pixel a few samples leave noise
    in it (see :data:`CLEAN_TEXTURE_SPP`).
    """
    start = time.perf_counter()
    textured = np.asarray(textured, dtype=bool)[..., None]
    texture = safe_albedo(albedo)
    surface = (np.asarray(albedo) > 0).any(axis=-1, keepdims=True) | textured
    flat = np.where(textured, surface, albedo).astype(np.float64)
    shading = np.where(textured, np.asarray(color, dtype=np.float64) / texture, color)
    out, setup, first = _run_filter(shading, flat, normal, quality, False)
    _record(quality, out.shape[:2], time.perf_counter() - start, setup, first)  # (the division in)
    if clean_texture:  # (its time is texture_seconds')
        texture = safe_albedo(_run_filter(albedo, None, None, TEXTURE_QUALITY, False)[0])
    return np.where(textured, out * texture, out)


def texture_seconds(pixels: int) -> float:
    """What :func:`denoise_shading`'s ``clean_texture`` call on ``pixels``
    pixels is expected to take: a call at :data:`TEXTURE_QUALITY` with both
    guides (:func:`expected_seconds`), which one on the albedo alone does not exceed."""
    return expected_seconds(pixels, TEXTURE_QUALITY)


def textured_pixels(shape_index: np.ndarray, albedo: np.ndarray,
                    diffuse: np.ndarray) -> np.ndarray:
    """Which traced pixels lie on a textured diffuse surface.

    A diffuse BSDF's albedo is its reflectance at the hit, with no noise, so
    where one surface's pixels disagree on it (by more than
    :data:`TEXTURE_CONTRAST`), the surface is textured: its radiance is the
    texture times a smooth shading.  Denoising that radiance on the sparse
    grid smooths the texture's fine detail with the noise, and dividing by a
    dark texel's albedo afterwards magnifies what was smoothed.

    Parameters
    ----------
    shape_index : ndarray of int, shape (n,)
        Each pixel's shape (1-based, 0: none), as the trace gives it.
    albedo : ndarray, shape (n, 3)
    diffuse : ndarray of bool, shape (shapes + 1,)
        Per shape index, whether its BSDF is purely diffuse with a reflectance
        that varies (the renderer's ``textured_diffuse_shapes``; entry 0
        unused): a one-colour surface's edge pixels disagree too, as they mix
        two surfaces' albedos.

    Examples
    --------
    >>> ids = np.array([1] * 10 + [2] * 10)
    >>> albedo = np.repeat([[0.05], [0.8]] * 5 + [[0.5]] * 10, 3, axis=1)
    >>> textured_pixels(ids, albedo, np.array([False, True, True])).tolist() == [True] * 10 + [False] * 10
    True
    """
    shape_index = np.asarray(shape_index)
    out = np.zeros(len(shape_index), dtype=bool)
    albedo = np.asarray(albedo, dtype=np.float64)
    # (the channels' mean, added in the order mean(axis=-1) adds them: the
    # same values, without its reduction over a strided axis)
    level = (albedo[:, 0] + albedo[:, 1] + albedo[:, 2]) / 3.0
    seen = np.flatnonzero(np.bincount(shape_index.ravel(), minlength=1)[1:]) + 1
    for index in seen[seen < len(diffuse)]:
        if not diffuse[index]:
            continue
        mine = shape_index == index
        lit = level[mine & (level > 0)]
        if len(lit) < TEXTURE_MIN_PIXELS:
            continue
        low, high = np.percentile(lit, [5, 95])
        if high > TEXTURE_CONTRAST * low:
            out |= mine
    return out


def denoise_grid(radiance: np.ndarray, albedo: np.ndarray | None = None,
                 normal: np.ndarray | None = None, denoiser: str = "oidn",
                 quality: str | None = None, textured: np.ndarray | None = None,
                 exact: np.ndarray | None = None) -> np.ndarray:
    """The grid image ``radiance`` (rows, columns, 3), denoised with its guides.

    ``albedo`` and ``normal`` are the grid pixels' own (the trace's, 0 where
    the pixel centre sees no surface). Only ``denoiser="oidn"`` exists; the
    public boundary (:class:`~mitsuba_mrt.types.MRTParams`) has checked it.
    ``quality``: default :data:`GRID_QUALITY`.  ``textured`` (rows, columns)
    marks the pixels on textured diffuse surfaces (:func:`textured_pixels`):
    theirs is the denoised shading, ``radiance / albedo`` denoised with a
    flat albedo guide, times their albedo, in the same OIDN call as the
    others (:func:`denoise_shading`).  ``exact`` (rows, columns) marks the
    pixels whose samples all agreed (a constant background, an emitter seen
    directly): they keep their values, which a denoiser can only blur.
    """
    quality = quality or GRID_QUALITY
    if textured is not None and albedo is not None and np.any(textured):
        out = denoise_shading(radiance, albedo, normal, textured, quality)
    else:
        out = denoise_image(radiance, albedo, normal, quality)
    if exact is not None:
        out = np.where(np.asarray(exact, dtype=bool)[..., None], radiance, out)
    return out
