"""The experiments of the ``bench`` command: what each one sweeps and compares.

An :class:`Experiment` is a list of :class:`Point` s; a point is one scene
file with its ``<default>`` values and spp (loaded once, its full render
shared), and holds one or more :class:`Setting` s, the MRT parameters to try
on it. Every experiment sweeps one parameter of the report (its Figs. 6-10)
or, for ``tradeoff``, shows every method and setting as a (time, error)
point; ``gallery`` runs every mode on ordinary Mitsuba scenes
(``scenes_xml/gallery``) with their own parameters.

Methods, by name: ``full`` (the plain Mitsuba render with the same
integrator and spp, the reference: relative time 1), ``mrt-<mode>`` for each
reconstruction mode of :data:`mitsuba_mrt.modes.MODES` at run time, except
the scene-agnostic baselines, which keep their names (``nearest``,
``bicubic``). All of them trace the same grid with the same seed.

How a point is measured is :mod:`.measure`; how the results are written,
:mod:`.report`; running a whole experiment, :mod:`.run`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import MRTError

#: The experiments, in the order ``all`` runs them.
EXPERIMENTS = ("fraction", "filter", "pixels", "objects", "lights", "tradeoff", "gallery",
               "denoise")

#: Modes that are scene-agnostic upsampling of the grid keep their own names.
BASELINES = ("nearest", "bicubic")

FULL = "full"
EQUAL_TIME = "full-equal-time"
#: At a stochastic point of the other experiments, each method is also set
#: against the full render denoised by OIDN at the spp whose total (aux
#: render and denoising included) is closest to the method's: with the
#: albedo and normal guides, and without them.
OIDN_EQUAL_TIME = "oidn-equal-time"
OIDN_NOAUX_EQUAL_TIME = "oidn-noaux-equal-time"
#: The rows that repeat another method's time (``matched_method``).
EQUAL_TIME_BASELINES = (EQUAL_TIME, OIDN_EQUAL_TIME, OIDN_NOAUX_EQUAL_TIME)

#: ``auto`` runs a pilot and may render in full, so it is compared on request
#: (``--methods auto``) rather than by default.
AUTO = "mrt-auto"

#: The report's figure each experiment reproduces.
FIGURES = {"fraction": "Fig. 6", "filter": "Fig. 7", "pixels": "Fig. 8", "objects": "Fig. 9",
           "lights": "Fig. 10", "tradeoff": "none (a user's choice of setting)",
           "gallery": "none (ordinary scenes)",
           "denoise": "none (issue 15: the MRT against a denoiser)"}

#: The gallery's scenes: ``scenes_xml/gallery/<name>.xml``, written by
#: ``tools/make_gallery.py``; each has ``<default>`` s ``res`` and ``spp``.
GALLERY_SCENES = ("checker_border", "cornell", "crop_rgba", "envmap_objects", "instanced",
                  "materials", "room", "spot_textures", "two_sensors")


def gallery_defines(name: str, res: int) -> dict:
    """The ``-D`` values that render gallery scene ``name`` at ``res`` a side:
    ``crop_rgba``'s crop window needs a film that holds it at its offset.

    Examples
    --------
    >>> gallery_defines("crop_rgba", 256), gallery_defines("cornell", 256)
    ({'res': 256, 'film_res': 384}, {'res': 256})
    """
    return {"res": res, **({"film_res": res + 128} if name == "crop_rgba" else {})}


#: The gallery's methods (``full`` besides): every MRT mode a user picks, and
#: the baseline a user would reach for without the MRT.
GALLERY_METHODS = ("mrt-auto", "mrt-paper", "mrt-fast", "mrt-refine", "mrt-idpass", "bicubic")

#: The gallery's picture of a scene: reference | these | error map of the first.
GALLERY_PICTURE = ("mrt-auto", "bicubic")

#: The denoise experiment's spp ladder, as asked of the scene's sampler (one
#: that rounds, like ``stratified`` to squares, is measured at each count it
#: takes, once); the top is the full render every time is relative to.
DENOISE_LADDER = (1, 2, 4, 8, 16, 32, 64)
DENOISE_LADDER_QUICK = (1, 4)

#: The MRT modes of the denoise experiment, each with and without ``denoise``.
DENOISE_METHODS = ("mrt-paper", "mrt-fast", "mrt-refine", "mrt-idpass")

#: The full render denoised by OIDN, with the ``aov`` integrator's albedo and
#: normal (1 spp, time included) and without them, at each of these qualities.
OIDN = "oidn"
OIDN_NOAUX = "oidn-noaux"
OIDN_QUALITIES = ("fast", "balanced")
#: OIDN's quality in the other experiments' ``oidn`` baselines: the cheap
#: one, as the MRT's own ``denoise`` stage uses.
OIDN_BASELINE_QUALITY = "fast"

#: The MRT's method name with ``denoise="oidn"``: ``mrt-fast+oidn``, and with
#: another ``denoise_quality`` than ``fast``: ``mrt-fast+oidn-balanced``.
DENOISED_SUFFIX = "+oidn"
#: The MRT methods the denoise experiment also runs with ``denoise_quality``
#: ``balanced`` (the cheap one and the one of least error at high spp).
DENOISE_BALANCED_METHODS = ("mrt-fast", "mrt-idpass")
#: The other sample fractions the denoise experiment runs (those of the
#: tradeoff experiment), with and without ``denoise``, with these methods.
DENOISE_OTHER_FRACTIONS = (0.05, 0.2)
DENOISE_FRACTION_METHODS = ("mrt-fast",)
#: Beyond the ladder's top, on the gallery: the spp at which the MRT
#: configurations of :data:`DENOISE_BEYOND_CONFIGS` (sample fraction, methods;
#: with ``denoise``) are measured too, those closest to the full render's error
#: at 64 spp, so the equal-error table says at what time they reach it.
DENOISE_BEYOND = (128, 256)
DENOISE_BEYOND_QUICK = (8,)
DENOISE_BEYOND_CONFIGS = ((0.1, ("mrt-refine", "mrt-idpass")), (0.2, ("mrt-fast",)))


def denoised_name(method: str, params: dict) -> str:
    """The row name of MRT ``method`` run with ``params`` (``denoise`` and its quality)."""
    if params.get("denoise", "none") == "none":
        return method
    quality = params.get("denoise_quality", "fast")
    return method + DENOISED_SUFFIX + ("" if quality == "fast" else f"-{quality}")


def denoised_mode(name: str) -> tuple[str, str]:
    """(the MRT method, the denoising suffix or "") of a row name: ``("mrt-fast", "+oidn")``."""
    base, plus, rest = name.partition("+")
    return base, plus + rest


# --------------------------------------------------------------------------- methods

def method_name(mode: str) -> str:
    """CSV name of a reconstruction mode: baselines keep theirs, others get ``mrt-``."""
    return mode if mode in BASELINES else f"mrt-{mode}"


def available_methods() -> dict[str, str | None]:
    """Every method name now available -> its mode (``None`` for ``full``)."""
    from ..modes import MODES

    return {FULL: None, **{method_name(m): m for m in MODES}, AUTO: "auto"}


def resolve_methods(names=None) -> list[str]:
    """The methods to run, ``full`` first; ``names`` is a list or a comma list.

    A mode's bare name (``paper``) is accepted for its method (``mrt-paper``).
    ``full`` always runs: it is the reference.
    """
    methods = available_methods()
    if names is None:
        return [name for name in methods if name != AUTO]
    if isinstance(names, str):
        names = [n.strip() for n in names.split(",") if n.strip()]
    if not names:
        raise MRTError("--methods is empty")
    by_mode = {mode: name for name, mode in methods.items() if mode is not None}
    chosen = [FULL]
    for name in names:
        name = name if name in methods else by_mode.get(name, name)
        if name not in methods:
            raise MRTError(f"unknown method {name!r}; choose from {', '.join(methods)}")
        if name not in chosen:
            chosen.append(name)
    return chosen


# --------------------------------------------------------------------------- experiments

@dataclass
class Setting:
    """One set of MRT parameters at a point: ``x`` is its swept value; ``methods``
    the methods it is measured with (empty: every one); ``ladder`` the spp it is
    measured at in a ladder experiment (empty: the experiment's ladder)."""

    params: dict
    x: float = math.nan
    label: str = ""
    group: str = ""
    methods: tuple = ()
    ladder: tuple = ()

    def applies_to(self, method: str) -> bool:
        return not self.methods or method in self.methods


def setting_pairs(point: "Point", methods) -> list:
    """(setting index, method) of every method measured at every setting of ``point``."""
    return [(s, m) for s, setting in enumerate(point.settings) for m in methods
            if setting.applies_to(m)]


@dataclass
class Point:
    """One scene file with its defines and spp; the full render is shared by its settings."""

    scene: str
    defines: dict
    spp: int
    settings: list
    x: float = math.nan
    group: str = ""

    @property
    def integrator(self) -> str:
        return str(self.defines.get("integrator", "matte"))

    @property
    def defines_text(self) -> str:
        """The defines as the CSV writes them: ``res=64;integrator=matte``."""
        return ";".join(f"{k}={v}" for k, v in self.defines.items())


@dataclass
class Experiment:
    """A sweep: its points, the name of the swept value and the setting drawn in the triptych.

    ``kind`` says how it is reported: ``sweep`` (error and time against the
    swept value), ``tradeoff`` (time against error) or ``gallery`` (a table
    per scene and method). ``representative`` is (point, setting) of the
    triptych; ``pictures``, when given, replaces the triptych with a picture
    of every point's first setting: reference | these methods | error map
    of the first one. ``full_spp_sweep`` adds a row for the full render at
    every spp tried (stochastic points). ``methods`` are the default
    methods (None: every mode but ``auto``); ``cache_converged`` keeps the
    converged references on disk, under the output folder, for reruns.
    """

    name: str
    title: str
    x_name: str
    x_label: str
    points: list
    representative: tuple = (0, 0)
    log_x: bool = False
    full_spp_sweep: bool = False
    kind: str = "sweep"
    pictures: tuple = ()
    methods: tuple | None = None
    cache_converged: bool = False
    ladder: tuple = ()


def _fraction_settings(fractions, sigma=1.0, cutoff=0.05, group=""):
    return [Setting({"sample_fraction": f, "filter_sigma": sigma, "filter_cutoff": cutoff},
                    x=f, label=f"f={f:g}", group=group) for f in fractions]


def _closest(values, target) -> int:
    return int(np.argmin([abs(v - target) for v in values]))


def check_res(res: int) -> int:
    """``res`` (an image side that ``--res`` sets), refused below 8 pixels.

    Examples
    --------
    >>> check_res(256)
    256
    """
    if res < 8:
        raise MRTError(f"--res must be >= 8, got {res}")
    return res


def check_repeats(repeats) -> int:
    """``repeats`` (the timed rounds of every method), refused where it is not
    an integer >= 1.

    Examples
    --------
    >>> check_repeats(3)
    3
    """
    if int(repeats) != repeats or repeats < 1:
        raise MRTError(f"--repeats must be an integer >= 1, got {repeats}")
    return int(repeats)


def build_experiment(name: str, quick: bool = False, res: int | None = None) -> Experiment:
    """The points of experiment ``name``; ``quick``: a reduced sweep at low resolution.

    ``res`` overrides the image side of every experiment but ``pixels``.
    """
    if name not in EXPERIMENTS:
        raise MRTError(f"unknown experiment {name!r}; choose one of {', '.join(EXPERIMENTS)}, all")
    if res is not None and name == "pixels":
        raise MRTError("--res does not apply to the pixels experiment (it sweeps the resolution)")
    side = check_res(res) if res is not None else (64 if quick else 200)
    matte = {"integrator": "matte", "spp": 1}

    if name == "fraction":
        fractions = (0.05, 0.1, 0.2) if quick else tuple(round(0.025 * k, 3) for k in range(1, 11))
        settings = _fraction_settings(fractions)
        point = Point("paper_fraction.xml", {"res": side, **matte}, 1, settings)
        return Experiment(name, "MRT against the sample fraction", "sample_fraction",
                          "sample fraction f", [point], (0, _closest(fractions, 0.1)))
    if name == "filter":
        sigmas = (1.0, 4.0) if quick else (1.0, 2.0, 4.0, 8.0)
        cutoffs = (0.05, 0.25) if quick else (0.05, 0.10, 0.15, 0.20, 0.25)
        settings = [Setting({"sample_fraction": 0.1, "filter_sigma": s, "filter_cutoff": c},
                            x=c, label=f"sigma={s:g} cutoff={c:g}", group=f"sigma={s:g}")
                    for s in sigmas for c in cutoffs]
        point = Point("paper_fraction.xml", {"res": side, **matte}, 1, settings)
        return Experiment(name, "MRT against the Gaussian filter's sigma and cutoff (f = 0.1)",
                          "filter_cutoff", "normalised cutoff", [point], (0, 0))
    if name == "pixels":
        scales = (0.1, 0.15, 0.2) if quick else tuple(0.5 + 0.25 * k for k in range(11))
        points = []
        for a in scales:
            side_a = int(400 * a)
            points.append(Point("paper_fig1.xml", {"res": side_a, **matte}, 1,
                                _fraction_settings((0.1,)), x=side_a))
            points[-1].settings[0].x = side_a
            points[-1].settings[0].label = f"{side_a}x{side_a}"
        return Experiment(name, "MRT against the number of pixels (f = 0.1)", "pixels",
                          "pixels a side", points,
                          (_closest([p.x for p in points], 400), 0))
    if name in ("objects", "lights"):
        counts = {"objects": (0, 5, 10) if quick else tuple(range(11)),
                  "lights": (1, 9, 19) if quick else tuple(range(1, 20, 2))}[name]
        points = []
        for n in counts:
            settings = _fraction_settings((0.1,))
            settings[0].x, settings[0].label = n, f"N={n}"
            points.append(Point(f"paper_{name}_{n}.xml", {"res": side, **matte}, 1, settings, x=n))
        what = "spheres" if name == "objects" else "point lights"
        return Experiment(name, f"MRT against the number of {what} (f = 0.1)", "N",
                          f"number of {what}", points, (len(points) - 1, 0))
    if name == "gallery":
        return _gallery(quick, res)
    if name == "denoise":
        return _denoise(quick, res)
    # tradeoff
    side = res or (64 if quick else 400)
    spp = 4 if quick else 64
    fractions = (0.1, 0.2) if quick else (0.05, 0.1, 0.2)
    path_group, matte_group = f"path {spp} spp", "matte 1 spp"
    points = [
        Point("paper_fig1.xml", {"res": side, "integrator": "path", "spp": spp, "jitter": "true"},
              spp, _fraction_settings(fractions, group=path_group), group=path_group),
        Point("paper_fig1.xml", {"res": side, **matte}, 1,
              _fraction_settings(fractions, group=matte_group), group=matte_group),
    ]
    return Experiment(name, "Time against error: every method and setting on the Fig. 1 scene",
                      "sample_fraction", "total time (s)", points,
                      (0, _closest(fractions, 0.1)), log_x=True, full_spp_sweep=True,
                      kind="tradeoff")


def _gallery(quick: bool, res: int | None) -> Experiment:
    """Every scene of :data:`GALLERY_SCENES` at its own MRT defaults, ``res`` a side."""
    from ..types import MRTParams

    side = res or (32 if quick else 128)
    spp = 4 if quick else 64
    defaults = MRTParams()
    params = {"sample_fraction": defaults.sample_fraction,
              "filter_sigma": defaults.filter_sigma, "filter_cutoff": defaults.filter_cutoff}
    points = [Point(f"gallery/{name}.xml", {"res": side, "spp": spp}, spp,
                    [Setting(dict(params), label="defaults", group=name)], group=name)
              for name in GALLERY_SCENES]
    return Experiment("gallery", "Every mode on ordinary Mitsuba scenes", "scene", "scene",
                      points, kind="gallery", pictures=GALLERY_PICTURE,
                      methods=GALLERY_METHODS, cache_converged=True)


def _denoise(quick: bool, res: int | None) -> Experiment:
    """The Fig. 1 scene (``path``, jittered) and every gallery scene, over a ladder of spp.

    Each point has the MRT's defaults without and with ``denoise="oidn"``,
    measured with every mode, and for some modes ``denoise_quality``
    ``balanced`` and the other fractions of :data:`DENOISE_OTHER_FRACTIONS`;
    the runner (:class:`.measure.DenoiseRunner`) runs them, the full render
    and ``oidn`` at every spp of the ladder. The gallery's points also have
    :data:`DENOISE_BEYOND_CONFIGS` at the spp of :data:`DENOISE_BEYOND`
    (settings of the same labels, so their rows extend the same curves).
    """
    from ..types import MRTParams

    ladder = DENOISE_LADDER_QUICK if quick else DENOISE_LADDER
    spp = max(ladder)
    fraction = MRTParams().sample_fraction

    def setting(f, denoise, quality=None, methods=(), beyond=()):
        params = {"sample_fraction": f, "denoise": denoise}
        label = f"f={f:g}" + ("" if denoise == "none" else f", denoise={denoise}")
        if quality is not None:
            params["denoise_quality"], label = quality, label + f", quality={quality}"
        return Setting(params, label=label, methods=methods, ladder=beyond)

    settings = [setting(fraction, "none"), setting(fraction, "oidn"),
                setting(fraction, "oidn", "balanced", DENOISE_BALANCED_METHODS)]
    settings += [setting(f, d, methods=DENOISE_FRACTION_METHODS)
                 for f in DENOISE_OTHER_FRACTIONS for d in ("none", "oidn")]
    fig1 = Point("paper_fig1.xml", {"res": res or (32 if quick else 400), "integrator": "path",
                                    "spp": spp, "jitter": "true"}, spp, settings,
                 group="paper_fig1")
    beyond = DENOISE_BEYOND_QUICK if quick else DENOISE_BEYOND
    beyond = [setting(f, "oidn", methods=methods, beyond=beyond)
              for f, methods in DENOISE_BEYOND_CONFIGS]
    scenes = GALLERY_SCENES[:1] if quick else GALLERY_SCENES
    gallery = [Point(f"gallery/{name}.xml", {"res": res or (24 if quick else 128), "spp": spp},
                     spp, settings + beyond, group=name) for name in scenes]
    return Experiment("denoise", "The MRT against the full render denoised by Intel Open "
                      "Image Denoise", "spp", "spp", [fig1, *gallery], kind="denoise",
                      methods=DENOISE_METHODS[1:2] if quick else DENOISE_METHODS,
                      cache_converged=True, ladder=ladder)
