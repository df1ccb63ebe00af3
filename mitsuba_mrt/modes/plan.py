"""The planner behind mode ``auto``: which render to run, from predicted costs and errors.

A :class:`Candidate` is one way to make the image (a full render at some
spp, the same denoised, an MRT mode), with the seconds and the error a pilot
predicted for it; :func:`choose` picks one under a time limit and a quality
target, the way Blender Cycles' controls read: the cheapest candidate that
meets the target, among those that fit the time; where none meets it, the
most accurate that fits.  Nothing here measures or renders; the pilot
(:mod:`mitsuba_mrt.renderer.pilot`) does.

Examples
--------
>>> a = Candidate("full", "full", 64, seconds=1.0, error=0.05)
>>> b = Candidate("full+oidn", "denoised", 4, seconds=0.1, error=0.03)
>>> choose([a, b], target_error=0.05).choice.name
'full+oidn'
>>> choose([a, b], time_limit=0.05).reason
'nothing fits the time limit: the cheapest candidate'
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..errors import MRTError

#: The kinds of candidate: ``full`` is ``mi.render`` itself; ``denoised`` a
#: full render with a box pixel filter through OIDN, with albedo and normal
#: guides from the same samples; ``passes`` the same without a denoiser;
#: ``mrt`` one of the MRT's modes.
KINDS = ("full", "denoised", "passes", "mrt")


@dataclass(frozen=True)
class Candidate:
    """One way to render the image, with its predicted cost and error.

    Attributes
    ----------
    name : str
        What a user reads: ``full``, ``full+oidn``, ``refine+oidn``, ...
    kind : {'full', 'denoised', 'passes', 'mrt'}
    spp : int
        Samples per traced pixel.
    mode : str or None
        The MRT mode (``fast``, ``refine``, ``idpass``) of an ``mrt`` candidate.
    denoise : bool
        Whether OIDN runs (on the image, or on the MRT's grid).
    seconds : float or None
        Predicted wall time of the render, the pilot's and kernel compilation
        left out (None: not predicted).
    error : float or None
        Predicted relative RMS error against the converged render (see
        :mod:`mitsuba_mrt.renderer.pilot`; None: not predicted).
    compile_s : float
        Predicted seconds of compiling the kernels this candidate needs that
        the process has not compiled yet (counted only against a time limit).
    quality : str or None
        OIDN's preset, where the plan chose it (``auto``'s passes).
    shading : bool
        Whether OIDN saw the textured diffuse surfaces as their shading
        (``auto``'s passes).
    clean_texture : bool
        Whether that shading was multiplied back by the albedo denoised too
        (at 1-2 spp: :func:`~mitsuba_mrt.recon.denoise.denoise_shading`).
    fraction : float or None
        The share of the pixels an ``mrt`` candidate's grid traces, where
        the plan chose it (None: the render's ``sample_fraction``).
    """

    name: str
    kind: str
    spp: int
    mode: str | None = None
    denoise: bool = False
    seconds: float | None = None
    error: float | None = None
    compile_s: float = 0.0
    quality: str | None = None
    shading: bool = False
    clean_texture: bool = False
    fraction: float | None = None

    @property
    def label(self) -> str:
        """``name`` with its spp (and what the plan chose of OIDN's and of the
        grid): ``full+oidn @ 4 spp``, ``full+oidn @ 32 spp, OIDN high, textures
        as shading``, ``refine+oidn @ 32 spp, grid of 20 % of the pixels``."""
        return (f"{self.name} @ {self.spp} spp" + (f", OIDN {self.quality}" if self.quality
                                                   else "")
                + (", textures as shading" if self.shading else "")
                + (" (texture denoised)" if self.clean_texture else "")
                + (f", grid of {100 * self.fraction:.3g} % of the pixels"
                   if self.fraction is not None else ""))


@dataclass
class Plan:
    """What ``auto`` chose, among what, and why.

    Attributes
    ----------
    choice : Candidate
    reason : str
        Why, in a few words.
    candidates : list of Candidate
        Every candidate the pilot measured, with its predictions.
    target_error : float or None
        The error the choice had to meet (None under a time limit alone).
    time_limit : float or None
        The wall time asked for, seconds (None: no limit).
    budget_s : float or None
        What was left of the time limit for the render after the pilot.
    pilot_s : float
        Wall seconds of the pilot, its kernel compilation included.
    pilot_pixels : int
        Pixels the pilot traced (each trace counted).
    notes : list of str
        What the plan could not consider (OIDN missing, ...).
    passes : list of (int, float)
        For a denoised full render made in passes: after each round, the
        spp of the half that was denoised and its estimated error.
    """

    choice: Candidate
    reason: str
    candidates: list = field(default_factory=list)
    target_error: float | None = None
    time_limit: float | None = None
    budget_s: float | None = None
    pilot_s: float = 0.0
    pilot_pixels: int = 0
    notes: list = field(default_factory=list)
    passes: list = field(default_factory=list)


def choose(candidates: list, *, target_error: float | None = None,
           time_limit: float | None = None) -> Plan:
    """Pick one of ``candidates``.

    Parameters
    ----------
    candidates : list of Candidate
        At least one.
    target_error : float, optional
        The largest predicted error accepted; None: the most accurate is wanted.
    time_limit : float, optional
        Seconds the render may take (compilation of new kernels included);
        None: no limit.

    Returns
    -------
    Plan
        The cheapest candidate whose error meets ``target_error`` among those
        that fit ``time_limit``; where none meets it, the most accurate that
        fits; where none fits, the cheapest of all.  Ties go to the cheaper,
        then to the earlier in ``candidates``.
    """
    if not candidates:
        raise MRTError("the planner needs at least one candidate")

    def cost(c: Candidate) -> float:
        seconds = math.inf if c.seconds is None else c.seconds
        return seconds + (c.compile_s if time_limit is not None else 0.0)

    def error(c: Candidate) -> float:
        return math.inf if c.error is None else c.error

    fits = [c for c in candidates if time_limit is None or cost(c) <= time_limit]
    if not fits:
        choice, reason = min(candidates, key=cost), "nothing fits the time limit: the cheapest candidate"
    else:
        meeting = [c for c in fits if target_error is not None and error(c) <= target_error]
        if meeting:
            choice = min(meeting, key=cost)
            reason = "the cheapest that meets the target" + (
                " within the time limit" if time_limit is not None else "")
        else:
            choice = min(fits, key=lambda c: (error(c), cost(c)))
            reason = ("the most accurate within the time limit" if time_limit is not None
                      else "none meets the target: the most accurate")
    return Plan(choice, reason, list(candidates), target_error, time_limit, time_limit)
