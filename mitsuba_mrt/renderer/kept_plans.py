"""The plans a process's default renders measured, taken again by its later renders.

A default render whose held-out check keeps its MRT image (``auto``'s
``idpass+oidn`` or ``refine+oidn``) notes here what it took: its seconds
(the check's, and what recording its traces took, left out) and those of
its traces that grow with the spp.  A
default render whose denoised passes ended notes their spp, OIDN preset
and whether the textures were denoised as shading.  A later default
render of the same key (traced objects, pixels, spp, parameters) takes
that plan again (:func:`plan_again`), without the probes, the check or
the passes' estimates that chose it.  The plan (not what it took) is also
remembered for later processes (:mod:`mitsuba_mrt.runtime.memory`, under
the ``memory_key`` its callers give): a user's next process renders the
scene as a warm one would.

A later time-limited render of the same key takes a kept MRT plan,
unchecked, at the most spp whose expected time ends within the limit
(:meth:`KeptPlan.spp_within`), from a share of the checked spp (an eighth
for ``idpass``, a quarter for ``refine``) up to four times it: over that
range its error beside the alternative's at equal time holds, and its time
is a fixed part (the id pass, OIDN on the grid, the reconstruction) plus
the growing traces.  An spp rendered before is expected to take what its
replays took; another between two rendered before, what the line
through theirs says; else the checked spp's typical time split as the
checked renders split theirs (the growing traces' share of each render's
own seconds: a first render's kernel compilations swell its traces and its
total alike); either a little more for the recordings a new spp makes
(:mod:`.replay`).  A sampler that bakes its spp into the kernels
(:func:`.scene_query.sampler_bakes_spp`) would compile them at a new spp:
there only the spp rendered before count.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace

from ..modes.plan import Candidate
from ..runtime import memory
from ..runtime.recent import keep, note, typical

#: Plans kept, of the last this many keys (traced objects, pixels, spp, parameters).
KEPT_PLANS = 16
#: Renders kept per spp: a plan is expected to take their median.
PLAN_CALLS = 3
#: Under a time limit a kept plan renders from this share of its checked spp,
#: per mode, up to :data:`MOST_SPP_FACTOR` times it: ``idpass+oidn`` denoises
#: its grid, so fewer spp cost it about what they cost the alternative;
#: ``refine+oidn`` traces its edges' pixels at the spp, not denoised, and
#: falls behind sooner (``bench rival``'s time limits run these plans at such
#: spp: docs/BENCHMARKS.md).
LEAST_SPP_SHARE = {"idpass": 1 / 8, "refine": 1 / 4}
MOST_SPP_FACTOR = 4
#: The share of the growing traces' time that does not shrink with fewer
#: spp (each launch's fixed part; at more spp none is assumed, which
#: overstates their time a little).
LAUNCH_FIXED = 0.1
#: The traces whose time grows with the spp, per mode: the grid's, and for
#: ``refine`` its edges' (``idpass``'s id pass takes its own albedo samples).
GROWING = {"idpass": ("trace",), "refine": ("trace", "trace_more")}
#: A render at an spp not rendered before records its traces anew (their
#: layouts hold the spp, :mod:`.replay`): it is expected to take this many
#: times what the split says (the recordings added 5-10 % on three gallery
#: scenes at 256 and 512 px).
NEW_SPP_COST = 1.1
#: The spp tried are those of at most this many significant bits (8, 10, 12,
#: 14, 16, 20, ...): at most an eighth fewer than would fit, and few spp to
#: record.
SPP_BITS = 3

_plans: dict = {}


@dataclass
class KeptPlan:
    """A plan a default render kept (``choice``, its spp the render's: an MRT
    plan its check kept, or denoised passes) and what the MRT plan's
    renders took: per spp, the last :data:`PLAN_CALLS` renders' seconds (at
    another spp than the checked one, only renders that recorded nothing: a
    replay's time); at the checked spp, their growing traces' share of
    their seconds (:data:`GROWING`).

    Examples
    --------
    >>> plan = KeptPlan(Candidate("idpass+oidn", "mrt", 64, mode="idpass", denoise=True), "")
    >>> plan.seconds[64], plan.growing = [0.2], [0.4]
    >>> plan.expected(64), round(plan.expected(32), 3), round(plan.expected(128), 3)
    (0.2, 0.18, 0.308)
    >>> plan.spp_within(0.25, bakes=False), plan.spp_within(0.25, bakes=True)
    (80, 64)
    >>> plan.spp_within(0.1, bakes=False) is None
    True

    Between two spp rendered before, the line through their times:

    >>> plan.seconds[16] = [0.1]
    >>> round(plan.expected(32), 3), plan.spp_within(0.15, bakes=False)
    (0.147, 32)
    """

    choice: Candidate
    reason: str
    seconds: dict = field(default_factory=dict)
    growing: list = field(default_factory=list)
    #: Whether an earlier process remembered it (:func:`plan_again`).
    recalled: bool = False

    def expected(self, spp: int) -> float:
        """Seconds a render at ``spp`` is expected to take (see the module)."""
        if spp in self.seconds:
            return typical(self.seconds[spp])
        below = [s for s in self.seconds if s < spp]
        above = [s for s in self.seconds if s > spp]
        if below and above:  # between two measured spp: a render's time is a line in its spp
            lo, hi = max(below), min(above)
            t_lo, t_hi = typical(self.seconds[lo]), typical(self.seconds[hi])
            return NEW_SPP_COST * (t_lo + (t_hi - t_lo) * (spp - lo) / (hi - lo))
        checked = self.choice.spp
        more = spp / checked - 1.0
        grows = typical(self.growing) * (more if more > 0 else (1.0 - LAUNCH_FIXED) * more)
        return NEW_SPP_COST * typical(self.seconds[checked]) * (1.0 + grows)

    def spp_within(self, seconds: float, bakes: bool) -> int | None:
        """The most spp expected to take at most ``seconds``, of those rendered
        before and (unless ``bakes``) :func:`spp_ladder`'s; None where none is."""
        tried = set(self.seconds)
        if not bakes:
            checked = self.choice.spp
            least = math.ceil(checked * LEAST_SPP_SHARE[self.choice.mode])
            tried |= set(spp_ladder(max(1, least), MOST_SPP_FACTOR * checked))
        return max((spp for spp in tried if self.expected(spp) <= seconds), default=None)


def spp_ladder(least: int, most: int) -> list[int]:
    """The spp from ``least`` to ``most`` of at most :data:`SPP_BITS` significant bits.

    Examples
    --------
    >>> spp_ladder(8, 40)
    [8, 10, 12, 14, 16, 20, 24, 28, 32, 40]
    """
    top = 1 << (SPP_BITS - 1)
    values = {(top + m) << shift >> (SPP_BITS - 1)
              for shift in range(max(most, 1).bit_length() + 1) for m in range(top)}
    return sorted(v for v in values if least <= v <= most)


def note_checked(key: tuple, choice: Candidate, reason: str, seconds: float,
                 timings, recording_s: float = 0.0, memory_key: str | None = None,
                 grid_recording_s: float | None = None) -> None:
    """Keep what a render of ``choice`` (a plan its check kept, at its spp)
    took for ``key``: ``seconds`` (its check left out) and the share of
    them the growing traces of ``timings`` (:class:`~mitsuba_mrt.types.Timings`)
    took, each less what recording its traces' replays took
    (:func:`~.replay.recording_seconds`; a replay takes none of it): all
    traces' ``recording_s``, and the growing traces' own, where they are the
    grid's alone (:data:`GROWING`), ``grid_recording_s`` (None: all of it).
    Another plan for ``key`` starts anew; the plan is remembered under
    ``memory_key`` (:func:`_remember`)."""
    kept = _plans.get(key)
    if kept is None or kept.choice.name != choice.name:  # (the key holds the spp)
        kept = KeptPlan(choice, reason)
    kept.choice, kept.reason = replace(choice, seconds=None), reason
    recording_s = min(max(recording_s, 0.0), seconds)
    replayed = seconds - recording_s
    note(kept.seconds.setdefault(choice.spp, []), replayed, PLAN_CALLS)
    parts = GROWING[choice.mode]
    grid_alone = parts == ("trace",) and grid_recording_s is not None
    own_recording = min(max(grid_recording_s, 0.0), recording_s) if grid_alone else recording_s
    growing = sum(getattr(timings, part) for part in parts) - own_recording
    note(kept.growing, min(max(growing, 0.0) / replayed, 1.0) if replayed > 0 else 0.0,
         PLAN_CALLS)
    keep(_plans, key, kept, KEPT_PLANS)
    _remember(kept, memory_key)


def note_plan(key: tuple, choice: Candidate, reason: str,
              memory_key: str | None = None) -> None:
    """Keep ``choice``, the whole image's plan a default render of ``key``
    ended with (the denoised passes, their spp, preset and shading; without
    OIDN, the full render an MRT image that missed its check gave way to),
    and its ``reason``; remembered under ``memory_key`` (:func:`_remember`)."""
    kept = keep(_plans, key, KeptPlan(replace(choice, seconds=None), reason), KEPT_PLANS)
    _remember(kept, memory_key)


def _remember(kept: KeptPlan, memory_key: str | None) -> None:
    """Keep ``kept``'s plan and reason for later processes under ``memory_key``
    (None: not remembered)."""
    if memory_key is not None:
        memory.remember(memory_key, {"choice": asdict(kept.choice), "reason": kept.reason})


def _recalled(memory_key: str | None) -> KeptPlan | None:
    """The plan an earlier process remembered under ``memory_key``, without
    what it took (this process has not measured it); None where there is none
    or it is not whole.

    Examples
    --------
    >>> _recalled(None) is None
    True
    """
    value = None if memory_key is None else memory.recall(memory_key)
    try:
        choice = Candidate(**value["choice"])
        reason = value["reason"]
    except (KeyError, TypeError):
        return None
    if choice.kind not in ("mrt", "denoised", "full") or not isinstance(reason, str) or (
            not isinstance(choice.spp, int) or choice.spp < 1):
        return None
    return KeptPlan(choice, reason, recalled=True)


def note_render(key: tuple, spp: int, seconds: float, replayed: bool) -> None:
    """Keep what a render of ``key``'s kept MRT plan at ``spp`` took, where it
    ``replayed`` its traces (:mod:`.replay`): one that recorded took what a
    replay does not."""
    kept = _plans.get(key)
    if kept is not None and kept.choice.kind == "mrt" and replayed:
        note(kept.seconds.setdefault(spp, []), seconds, PLAN_CALLS)


def plan_again(key: tuple, memory_key: str | None = None
               ) -> tuple[Candidate, str, bool] | None:
    """(the plan kept for ``key``, or where none is, the one an earlier
    process remembered under ``memory_key``; its reason; whether it was
    remembered so), or None: what a default render takes again."""
    kept = _plans.get(key)
    if kept is None:
        kept = _recalled(memory_key)
        if kept is not None:
            keep(_plans, key, kept, KEPT_PLANS)
    return None if kept is None else (kept.choice, kept.reason, kept.recalled)


def plan_within(key: tuple, seconds: float, bakes: bool) -> tuple[Candidate, str] | None:
    """(the MRT plan kept for ``key`` at the most spp expected to end within
    ``seconds``, those seconds its own; its reason), or None: see the module."""
    kept = _plans.get(key)
    if kept is None or kept.choice.kind != "mrt" or kept.choice.spp not in kept.seconds:
        return None  # (none, or one recalled that this process has not timed)
    spp = kept.spp_within(seconds, bakes)
    if spp is None:
        return None
    choice = kept.choice if spp == kept.choice.spp else replace(kept.choice, error=None)
    return replace(choice, spp=spp, seconds=kept.expected(spp)), kept.reason


def growing_seconds(key: tuple, spp: int) -> float | None:
    """What the traces that grow with the spp (:data:`GROWING`: the grid's,
    for ``idpass``) of the plan kept for ``key`` are expected to take of a
    render at ``spp``: their share of the checked render's seconds; None
    where no plan is kept or its share was not measured."""
    kept = _plans.get(key)
    if kept is None or not kept.growing or not kept.seconds:
        return None
    return typical(kept.growing) * kept.expected(spp)


def clear() -> None:
    """Forget every kept plan."""
    _plans.clear()
