"""What a launch of passes costs, learnt from the launches so far.

:class:`LaunchCost` fits a line, a fixed part and one per spp, through
the launches :mod:`.progressive` has made (of this render and earlier
renders of the same scene and image size), and tells how many spp a
launch may have to end in the time left, where a launch of a new spp
records its kernels' replay anew (:mod:`.replay`) or compiles them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from .develop import spp_class

#: A launch planned during a render is to take at most the time left over
#: this (:class:`LaunchCost` counts a recording's extra; this is for the
#: machine's noise and the error of a line through this render's first,
#: recorded launch).  A render's first launch, sized by earlier renders'
#: replayed launches, has none: their line is moved up until none took
#: longer, and overestimates larger launches already.
ROUND_SAFETY = 1.15
#: Launches a :class:`LaunchCost` keeps (the last): an earlier render's
#: launches tell the next one's line (a time-limited render's launches
#: alone, 1 spp then a few large ones, rarely give it two sizes), and
#: fewer are enough for the line and keep one slow launch from holding it up
#: for long.
KEPT_LAUNCHES = 8
#: A 1-spp launch's share that is its fixed part, where neither a launch of
#: more spp nor its kernels' run time measured it (0.1-0.7 on the gallery
#: at 256 px): where it is less, a launch of k spp takes up to
#: 1 / (1 - this) times what the line says (``spot_textures``, 0.11: 1.16
#: times at 4 spp), and one such launch measures the line.
ONE_SIZE_FIXED = 0.25
#: The spp of a time-limited render's first launch where nothing tells its
#: cost (:meth:`LaunchCost.first`): 2, whose recording every larger launch
#: replays (a first launch of 1 spp would be recorded again for them).
UNMEASURED_FIRST = 2


def _replayed_s(launch: "Launch") -> float:
    """What ``launch`` would take replayed: its seconds less what recording
    took in it, at least its trace kernels' run time where measured (a
    recording call may run the kernels it records, and its time then holds
    theirs: a replay is not faster than its kernels).

    Examples
    --------
    >>> round(_replayed_s(Launch(8, 0.12, True, 0.09, False, 0.11)), 2)
    0.09
    """
    seconds = launch.seconds - (launch.recording or 0.0)
    return seconds if launch.execute is None else max(seconds, min(launch.execute,
                                                                    launch.seconds))


class Launch(NamedTuple):
    """One launch of passes, as :class:`LaunchCost` keeps it: its spp and
    seconds, whether it recorded its kernels' replay (:mod:`.replay`), its
    trace kernels' run time (:attr:`~mitsuba_mrt.runtime.jit.KernelSeconds.widest`),
    whether it was the first launch its process made of the scene (whose
    recording also paid for first uses), what recording added to it (None:
    not measured) and whether an earlier process made it (``elsewhere``:
    :mod:`mitsuba_mrt.runtime.memory`; this process records its class anew)."""

    spp: int
    seconds: float
    recorded: bool = False
    execute: float | None = None
    first: bool = False
    recording: float | None = None
    elsewhere: bool = False


@dataclass
class LaunchCost:
    """What a launch of passes costs: ``fixed + per_spp * spp`` seconds, the
    line through the replayed launches so far (``launches``: :class:`Launch`
    records, or plain (spp, seconds, recorded) tuples; a recorded one less
    what recording took, where measured) moved up until none took longer
    than it says; a launch of an spp whose recording class
    (:func:`~.develop.spp_class`: 1, or every larger spp where the sampler
    does not bake its spp) was not launched before records anew, which adds
    :attr:`record_s`.  Where a new spp compiles no kernel
    (``spp_compiles`` False: a sampler that does not bake its spp in,
    :func:`~.scene_query.sampler_bakes_spp`), what a launch spent compiling
    (a process's first, or the disk cache's first) is left out of its time.

    A launch's fixed part (its kernels' start, reading every pixel back)
    makes a 1-spp launch cost about two of a larger launch's spp.  Where the
    launches so far have one size, the part of them that is not their trace
    kernels' run time is taken as the fixed part (the kernels that read each
    pixel back are in it; the trace's run time also has a part that does
    not grow with the spp, so this line overestimates larger launches, never
    smaller ones by much); where that was not measured, a
    1-spp launch's fixed part is taken as :data:`ONE_SIZE_FIXED` of it, and
    another single size's as 0.

    Examples
    --------
    >>> cost = LaunchCost()
    >>> cost.add(1, 0.036, recorded=True); cost.add(1, 0.018); round(cost(4), 4)
    0.0765
    >>> round(cost.record_s, 3), cost.fits(0.05), cost.fits(0.07)
    (0.018, 2, 3)
    >>> cost.add(2, 0.032); round(cost(4), 3), cost.fits(0.075)  # (2 spp's recording replays)
    (0.06, 5)

    The trace kernels' run time splits a single size's launches (here a fixed
    0.012 s, and at most 0.008 s an spp):

    >>> cost = LaunchCost([Launch(1, 0.02, False, 0.006), Launch(1, 0.018, False, 0.006)])
    >>> round(cost(4), 3), cost.fits(0.05)
    (0.044, 4)

    A recorded launch's time tells what recording adds, not the line, and a
    cost's first launch tells it only until another launch has recorded:

    >>> cost = LaunchCost([(1, 0.045, True), (1, 0.020, False), (2, 0.040, True)])
    >>> round(cost.record_s, 3), cost.fits(0.1)
    (0.005, 6)

    A size launched before is expected to take what its launch took where
    that is less than the line says (a recorded launch less its recording):

    >>> cost = LaunchCost([Launch(9, 0.62, True, None, True, 0.15), (1, 0.08, False),
    ...                    (1, 0.08, False)], spp_compiles=True)
    >>> round(cost(9), 2), cost.first(0.5)
    (0.47, 9)

    Where a new spp compiles, only the spp launched before, and the
    :attr:`ladder`'s, are planned:

    >>> cost = LaunchCost([(1, 0.02, False), (4, 0.05, False)], spp_compiles=True)
    >>> cost.fits(0.12), cost.cheapest(), cost(2)
    (4, 1, inf)
    >>> cost.ladder = frozenset([4, 9, 16]); cost.fits(0.12)
    9

    Launches an earlier process made (:meth:`from_memory`) tell the line, and
    every class records anew, at what that process's first launch took
    beyond the line (recording and first uses); where a new spp compiles,
    theirs are on disk:

    >>> cost = LaunchCost.from_memory({"spp_compiles": True, "launches": [
    ...     [1, 0.15, True, 0.04, True, 0.1], [1, 0.045, False, 0.033, False, None],
    ...     [9, 0.27, False, 0.25, False, None]]}, spp_compiles=True)
    >>> round(cost(9), 3), cost.first(0.4), cost.first(0.3), cost.cheapest()
    (0.375, 9, 1, 1)
    """

    launches: list = field(default_factory=list)
    spp_compiles: bool = False
    #: spp whose launch has a recording already (another trace of the same
    #: layout made it: :meth:`~.api.GridTracer.pass_recorded`): it records
    #: nothing anew, and compiles nothing where ``spp_compiles``.
    replays: frozenset = frozenset()
    #: The line (fixed, per_spp) before any launch: a guess that overstates
    #: a first launch (the grid probe's, :func:`.auto_limit.preview_first`);
    #: None: a first launch is the cheapest.
    prior: tuple | None = None
    #: Where a new spp compiles: the spp a launch may have besides those
    #: launched before (:func:`~.auto_limit.launch_ladder`), few, so that
    #: Dr.Jit's disk cache holds their kernels once a scene's earlier
    #: time-limited renders have launched them (a first launch compiles them).
    ladder: frozenset = frozenset()
    #: The (spp, recorded) of this process's launches when they were last
    #: remembered (:meth:`note_remembered`), and how many were added since
    #: (:meth:`memory_due`).
    remembered: frozenset = frozenset()
    since_remembered: int = 0

    def __post_init__(self):
        self.launches = [Launch(*launch) for launch in self.launches]

    def memory(self) -> dict:
        """The launches, as :mod:`mitsuba_mrt.runtime.memory` keeps them for
        later processes (:meth:`from_memory`)."""
        return {"spp_compiles": self.spp_compiles,
                "launches": [list(launch[:6]) for launch in self.launches]}

    def note_remembered(self) -> None:
        """Note that :meth:`memory` was kept: :meth:`memory_due` is False
        until another launch is due to be."""
        self.remembered = self._kinds_here()
        self.since_remembered = 0

    def memory_due(self) -> bool:
        """Whether later processes lack what this one learnt: a launch of a
        kind (spp, recorded) since the launches were last remembered
        (:meth:`note_remembered`), or as many launches as it keeps (their
        window moved on).  A scene rendered again and again writes its
        memory once in so many renders.

        Examples
        --------
        >>> cost = LaunchCost(); cost.add(8, 0.2, recorded=True); cost.memory_due()
        True
        >>> cost.note_remembered(); cost.add(8, 0.1); cost.memory_due()
        True
        >>> cost.note_remembered(); cost.add(8, 0.1); cost.memory_due()
        False
        """
        return self.launched_here and (not self._kinds_here() <= self.remembered
                                       or self.since_remembered >= KEPT_LAUNCHES)

    def _kinds_here(self) -> frozenset:
        """The (spp, recorded) of this process's launches kept."""
        return frozenset((launch.spp, launch.recorded) for launch in self.launches
                         if not launch.elsewhere)

    @classmethod
    def from_memory(cls, value: dict | None, spp_compiles: bool) -> "LaunchCost | None":
        """The cost :meth:`memory` kept, its launches made ``elsewhere``; None
        where ``value`` is not such a record, or is of a sampler that
        ``spp_compiles`` differently."""
        try:
            if value["spp_compiles"] is not spp_compiles:
                return None
            launches = [Launch(int(spp), float(seconds), bool(recorded),
                               None if execute is None else float(execute), bool(first),
                               None if recording is None else float(recording), True)
                        for spp, seconds, recorded, execute, first, recording
                        in value["launches"]]
        except (KeyError, TypeError, ValueError):
            return None
        numbers = [v for launch in launches for v in (launch.seconds, launch.execute,
                                                       launch.recording) if v is not None]
        if not launches or any(launch.spp < 1 for launch in launches) or not all(
                math.isfinite(v) and v >= 0.0 for v in numbers):
            return None
        return cls(launches[-KEPT_LAUNCHES:], spp_compiles)

    def add(self, spp: int, seconds: float, recorded: bool = False,
            compile_s: float = 0.0, execute_s: float | None = None,
            recording_s: float | None = None) -> None:
        """Add a launch (``compile_s``: what of it compiled kernels;
        ``execute_s``: its trace kernels' run time; ``recording_s``: what it spent
        recording its kernels' replay, to which a new spp's compilation adds
        where ``spp_compiles``), the first if the cost holds none; only the
        last :data:`KEPT_LAUNCHES` are kept."""
        first = not self.launched_here
        if not self.spp_compiles:
            seconds -= compile_s
        elif recording_s is not None:
            recording_s += compile_s
        self.launches.append(Launch(
            int(spp), float(seconds), bool(recorded), None if not execute_s else float(execute_s),
            bool(first), None if not recorded or recording_s is None
            else float(np.clip(recording_s, 0.0, seconds))))
        del self.launches[:-KEPT_LAUNCHES]
        self.since_remembered += 1

    def _line(self) -> tuple[float, float]:
        """(fixed, per_spp) of a replayed launch: through the replayed
        launches and the recorded ones whose recording was measured (all of
        them where none was), each less what recording took; before any
        launch, :attr:`prior`."""
        # (a cost's first launch also paid for first uses; a line through small
        # replays alone misses what larger launches cost)
        measured = [launch for launch in self.launches if not launch.recorded
                    or (launch.recording is not None and not launch.first)]
        points = [launch._replace(seconds=_replayed_s(launch))
                  for launch in measured or self.launches]
        if not points:
            return self.prior or (0.0, 0.0)
        spp = np.array([launch.spp for launch in points], dtype=float)
        seconds = np.array([launch.seconds for launch in points])
        sizes = len(set(spp))
        slope = float(np.polyfit(spp, seconds, 1)[0]) if sizes > 1 else 0.0
        if slope > 0:  # the fitted slope, moved up until no launch took longer
            fixed = float(np.clip((seconds - slope * spp).max(), 0.0, seconds.min()))
        elif sizes > 1:
            fixed = 0.0
        elif all(launch.execute is not None for launch in points):
            fixed = float(np.clip(min(launch.seconds - launch.execute for launch in points),
                                  0.0, seconds.min()))
        else:
            fixed = ONE_SIZE_FIXED * float(seconds.min()) if set(spp) == {1} else 0.0
        return fixed, float(((seconds - fixed) / spp).max())

    @property
    def launched_here(self) -> bool:
        """Whether this process made a launch of the cost (not only an earlier one)."""
        return any(not launch.elsewhere for launch in self.launches)

    @property
    def recalled(self) -> bool:
        """Whether the cost holds launches of an earlier process (:meth:`from_memory`)."""
        return any(launch.elsewhere for launch in self.launches)

    @property
    def replayed(self) -> bool:
        """Whether some launch replayed its kernels (the line is a launch's cost)."""
        return not all(launch.recorded for launch in self.launches)

    @property
    def record_s(self) -> float:
        """What recording adds to a launch of a new spp: what this process's
        last recorded launch spent recording (where measured, else what it
        took beyond the line; with its compilation where ``spp_compiles``),
        other than a first launch where another recorded (its recording also
        paid for first uses, once); before this process recorded, what an
        earlier one's first launch took beyond the line
        (:meth:`_first_record_s`); 0 where no launch recorded, or every
        launch did and none measured it."""
        recorded = [launch for launch in self.launches if launch.recorded
                    and not launch.elsewhere]
        if not recorded:
            return self._first_record_s()
        recorded = [launch for launch in recorded if not launch.first] or recorded
        last = recorded[-1]
        if last.recording is not None:
            return last.recording
        if not self.replayed:
            return 0.0
        fixed, per_spp = self._line()
        return max(last.seconds - fixed - per_spp * last.spp, 0.0)

    def _first_record_s(self) -> float:
        """:attr:`record_s` before this process recorded: what the first
        launch of an earlier process (``elsewhere``) took beyond the line
        (its recording and first uses, as this process's first launch
        will), at least its measured recording; 0 where none recorded."""
        fixed, per_spp = self._line()
        recorded = [launch for launch in self.launches if launch.recorded]
        recorded = [launch for launch in recorded if launch.first] or recorded
        return max((max(launch.seconds - fixed - per_spp * launch.spp, launch.recording or 0.0)
                    for launch in recorded), default=0.0)

    def _new(self, spp: int, anywhere: bool = False) -> bool:
        """Whether a launch of ``spp`` records anew: no launch of this
        process (``anywhere``: of any process), nor :attr:`replays`, had an
        spp of its recording class."""
        kind = spp_class(spp, self.spp_compiles)
        launched = [launch.spp for launch in self.launches if anywhere or not launch.elsewhere]
        return all(kind != spp_class(other, self.spp_compiles)
                   for other in [*self.replays, *launched])

    def _unplanned(self, spp: int) -> bool:
        """Whether ``spp`` is not planned: where a new spp compiles
        (``spp_compiles``) and some spp has been launched, one that no launch,
        of this process or an earlier one, nor :attr:`replays` had, nor
        :attr:`ladder` holds, other than a process's first launch of 1 spp
        (the launch that measures the line where nothing else is known).
        Whether its kernels come from Dr.Jit's disk cache or compile
        (several seconds for some scenes) no recording tells; an earlier
        process's launch put them there, or for the ladder's few counts a
        scene's earlier time-limited renders (a new spp's cost,
        :attr:`record_s`, holds what this process's last recorded launch
        spent compiling, where it compiled)."""
        if (not (self.spp_compiles and self.launches) or (spp == 1 and not self.launched_here)
                or spp in self.ladder):
            return False
        return self._new(spp, anywhere=True)

    def __call__(self, spp: int) -> float:
        """Seconds a launch of ``spp`` is expected to take (recorded anew
        where no launch had that spp; infinite where :meth:`_unplanned`):
        the line's, or where less, what launches of ``spp`` took
        (:meth:`_replay_of`)."""
        if self._unplanned(spp):
            return math.inf
        fixed, per_spp = self._line()
        anew = self.record_s if self._new(spp) else 0.0  # (an earlier process's spp too)
        return min(fixed + per_spp * spp, self._replay_of(spp)) + anew

    def _replay_of(self, spp: int) -> float:
        """The least seconds a launch of ``spp`` took, less what recording took
        in it (a recorded launch counts where that was measured); infinite
        where none did.  A line through launches of one small size
        overestimates a large one (a stratifying sampler's few sizes:
        ``instanced``'s 1-spp launches put its 9 spp at 1.4 times what its
        own launch took, and a time limit then launched 1 spp at a time)."""
        return min((_replayed_s(launch) for launch in self.launches
                    if launch.spp == spp and (not launch.recorded or launch.recording is not None)),
                   default=math.inf)

    def cheapest(self) -> int:
        """The spp of the launch expected to cost least, of 1, those
        launched before and :attr:`replays` (only those two where a new spp
        compiles)."""
        sizes = [1, *self.replays] + [launch.spp for launch in self.launches]
        return min((spp for spp in sizes if not self._unplanned(spp)),
                   key=lambda spp: (self(spp), spp))

    def first(self, seconds: float) -> int:
        """The spp of a time-limited render's first launch, to end within
        ``seconds``: the most that :meth:`fits` them (the line through
        earlier renders' launches, with no :data:`ROUND_SAFETY`, or before
        any, the :attr:`prior`), else the cheapest.  Where a new spp
        compiles, only spp launched before and the :attr:`ladder`'s fit (a
        stratifying sampler's one launch of more spp beats several of fewer,
        each a stratum of its own; the rest of the time is filled after it).
        Before any launch and without a prior, where a new spp compiles nothing:
        :data:`UNMEASURED_FIRST` (the launch that measures the line, of the
        recording class of every larger launch).

        Examples
        --------
        >>> cost = LaunchCost([(9, 0.25, False)], spp_compiles=True, replays=frozenset([1]))
        >>> cost.first(0.1), cost.first(0.27), cost.first(0.4)
        (1, 9, 9)
        >>> LaunchCost().first(0.2), LaunchCost(prior=(0.02, 0.03)).first(0.2)
        (2, 6)
        """
        if not (self.launches or self.spp_compiles) and self.prior is None:
            return UNMEASURED_FIRST
        return self.fits(seconds) or self.cheapest()

    def fits(self, seconds: float) -> int:
        """The most spp a launch expected to take at most ``seconds`` may
        have (only those launched before or in :attr:`replays` or
        :attr:`ladder` where a new spp compiles)."""
        fixed, per_spp = self._line()
        if per_spp <= 0:
            return 0
        # (each at its expected seconds: an earlier process's, or the ladder's
        # never launched, with their recording)
        launched = [spp for spp in {launch.spp for launch in self.launches} | self.replays
                    | self.ladder if self(spp) <= seconds]
        if self.spp_compiles and self.launches:
            return max(launched + [0])
        def most(spent: float) -> int:  # (a fit's rounding is not a launch short)
            return math.floor((seconds - spent) / per_spp + 1e-9)
        replayed = most(fixed)  # (of a class recorded before)
        anew = [replayed if replayed > 0 and not self._new(replayed)
                else most(fixed + self.record_s)]
        return max(launched + anew + [0])
