"""Replaying a trace's kernels instead of tracing the integrator again.

Building a trace's kernels (Python and Mitsuba's C++ recording every
operation of the integrator, then hashing the result to find the compiled
kernel) costs tens of milliseconds per call whatever the image size: more
than the kernels themselves take on a small image or at a few spp.
:func:`drjit.freeze` records the kernels of a call and replays them on later
calls with the same inputs' layout, with new values (a new seed, a changed
texture) but without tracing.

Dr.Jit tells a frozen call's inputs apart by their Dr.Jit variables only, not
by the plain C++ members of Mitsuba objects: two ``path`` integrators that
differ only in ``max_depth`` look alike to it, and a recording of one would
be replayed for the other.  So a :class:`Replay` keeps a frozen function per
identity of the Mitsuba objects it traces (the scene, the sensor, the
integrator) and Python values the kernels bake in (``layout``).  A
change made through ``mi.traverse`` is an input like any other and is seen;
a changed attribute of a Python-defined plugin is not (create a new object).

Where Dr.Jit cannot record a trace (it raises), the trace runs plainly, and
is not tried again for those objects and layout.

Only traces whose size repeats from render to render are recorded (the
grid, the id pass), and sets whose size changes (``refine``'s edge pixels,
``idpass``'s thin regions) once padded to one of a few sizes
(:func:`padded_size`); a recording per size of those would be made for nothing.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import sys
import time
from collections import OrderedDict
from dataclasses import dataclass
from typing import Callable, NamedTuple

import drjit as dr

#: Frozen functions kept per kernel function (least recently used dropped
#: first): one per traced objects and layout, and a sweep cycles through many
#: (``bench denoise``: 3 fractions x 7 spp for the grid, 5 albedo sample counts
#: for the id pass, a few padded sizes of ``refine``'s edges per spp); a
#: recording holds kernels, not images.
RECORDINGS = 128
#: Traced object sets ((scene, sensor, integrator), (scene, sensor)) that keep
#: their token: their objects are held, so that no other object can take over
#: an identity (a freed object's ``id``) and be given their recordings; a set
#: whose scene nobody else holds any more is let go at the next trace.
KEPT_OBJECTS = 8

_tokens = itertools.count(1)
#: id tuple -> (the objects, held; their token), least recently used first.
_held: OrderedDict = OrderedDict()
#: Whether traces asked to may replay: the innermost :func:`replaying` block's.
_replaying = [True]
#: Every :class:`Replay` made (one per kernel function).
_instances: list = []
#: Seconds spent in calls that made a recording.
_recording_seconds = [0.0]


@contextlib.contextmanager
def replaying(enabled: bool):
    """Within the block, traces are recorded and replayed (``True``, as outside
    any block) or always traced anew (``False``: to measure what replaying
    saves, or to rule it out).

    Examples
    --------
    >>> with replaying(False):
    ...     _replaying[-1]
    False
    """
    _replaying.append(bool(enabled))
    try:
        yield
    finally:
        _replaying.pop()


def recordings() -> int:
    """How many recordings every :class:`Replay` has made so far (kept or dropped)."""
    return sum(replay.n_recordings for replay in _instances)


def recording_seconds() -> float:
    """Seconds spent so far in calls that made a recording: tracing the
    kernel function (its kernels compile and run when their outputs are
    read, mostly after the call)."""
    return _recording_seconds[0]


class Recorded(NamedTuple):
    """:func:`recordings` and :func:`recording_seconds` at one moment (:func:`recorded_so_far`)."""

    count: int
    seconds: float


def recorded_so_far() -> Recorded:
    """What every :class:`Replay` has recorded so far, and in how many seconds."""
    return Recorded(recordings(), recording_seconds())


@dataclass
class Recording:
    """What a :func:`recorded_during` block recorded, filled when it ends:
    how many recordings, the seconds they took, and whether they were the
    process's first."""

    count: int = 0
    seconds: float = 0.0
    first: bool = False


@contextlib.contextmanager
def recorded_during():
    """A :class:`Recording` of what the block records (the time a trace's
    replays save, and whether it recorded at all).

    Examples
    --------
    >>> with recorded_during() as made:
    ...     pass
    >>> made.count, made.seconds
    (0, 0.0)
    """
    before, made = recorded_so_far(), Recording()
    try:
        yield made
    finally:
        made.count = recordings() - before.count
        made.seconds = recording_seconds() - before.seconds
        made.first = before.count == 0 < made.count


def active() -> bool:
    """Whether traces asked to replay may (see :func:`replaying`)."""
    return _replaying[-1]


def clear_recordings() -> None:
    """Drop every :class:`Replay`'s recordings, the layouts it could not record,
    and the objects held for their tokens: later traces are recorded anew, and
    :func:`recordings` counts from zero again.  Tokens are not given again."""
    for replay in _instances:
        replay.clear()
    _held.clear()


#: Sizes a padded pixel set is rounded up to: a geometric series of this
#: ratio (at most 19 % of the traced pixels are padding).
PAD_RATIO = 2.0 ** 0.25


def padded_size(count: int) -> int:
    """The size of the series :data:`PAD_RATIO` at or above ``count``.

    Examples
    --------
    >>> [padded_size(n) for n in (1, 2, 3, 100, 101, 1000)]
    [1, 2, 4, 108, 108, 1024]
    """
    if count <= 1:
        return max(count, 0)
    k = math.ceil(math.log(count, PAD_RATIO) - 1e-9)
    return max(count, math.ceil(PAD_RATIO ** k - 1e-6))


class Replay:
    """Call ``kernel`` plainly, or replay a recording of it.

    Each (objects, layout) has a frozen function of its own: Dr.Jit's own
    key does not tell a frozen call's plain Python values apart reliably (of
    calls whose tuples of small ints differ, it replayed another's recording
    for many), so the Python values never reach it.

    Parameters
    ----------
    kernel : callable
        Builds and evaluates the kernels.  Everything they depend on is an
        argument: Mitsuba objects, Dr.Jit arrays (any size), and last a tuple
        ``layout`` of the Python values it bakes in (sizes, flags).
    """

    def __init__(self, kernel: Callable):
        self.plain = kernel  # traced on each call
        #: (token, layout) -> its frozen function, least recently used first
        self.frozen: OrderedDict = OrderedDict()
        self._dropped = 0  # recordings made by the frozen functions let go
        self._failed: set = set()  # (token, layout) that Dr.Jit could not record
        _instances.append(self)

    @property
    def n_recordings(self) -> int:
        """Recordings made so far (kept or dropped)."""
        return self._dropped + sum(f.n_recordings for f in self.frozen.values())

    def clear(self) -> None:
        """Drop every recording and the layouts that could not be recorded."""
        self.frozen.clear()
        self._failed.clear()
        self._dropped = 0

    def recorded(self, objects: tuple, layout: tuple) -> bool:
        """Whether a call with these ``objects`` and ``layout`` would replay
        a recording (one was made, and replays are on)."""
        frozen = self.frozen.get((token(objects), layout))
        return _replaying[-1] and frozen is not None and frozen.n_recordings > 0

    def layouts(self, objects: tuple) -> list[tuple]:
        """The layouts recorded for these ``objects`` (kept, or being recorded)."""
        held = token(objects)
        return [layout for owner, layout in self.frozen if owner == held]

    def __call__(self, *args, objects: tuple, record: bool):
        """``kernel(*args)``; with ``record``, from the recording for these
        ``objects`` (the Mitsuba objects among ``args``) and layout
        (``args[-1]``), made now if there is none."""
        if not (record and _replaying[-1]):
            return self.plain(*args)
        key = (token(objects), args[-1])
        if key in self._failed:
            return self.plain(*args)
        frozen = self.frozen.get(key)
        if frozen is None:
            frozen = self.frozen[key] = dr.freeze(self.plain, warn_after=1 << 30)
            if len(self.frozen) > RECORDINGS:
                self._dropped += self.frozen.popitem(last=False)[1].n_recordings
        self.frozen.move_to_end(key)
        made, begin = frozen.n_recordings, time.perf_counter()
        try:
            return frozen(*args)
        except RuntimeError:  # Dr.Jit cannot record or replay these inputs
            self._failed.add(key)
            return self.plain(*args)
        finally:
            if frozen.n_recordings > made:
                _recording_seconds[0] += time.perf_counter() - begin


def token(objects: tuple) -> int:
    """The token of these Mitsuba objects (a scene first): the same while
    they live, never given to others (unlike their ``id``, which a later
    scene's objects may be given once these are freed); the key of what is
    kept per traced objects, here and in ``auto``."""
    _release_dropped()
    ids = tuple(id(o) for o in objects)
    held = _held.get(ids)
    if held is not None:  # held, so these very objects: no other can have their ids
        _held.move_to_end(ids)
        return held[1]
    new = next(_tokens)
    _held[ids] = (objects, new)
    if len(_held) > KEPT_OBJECTS:
        _held.popitem(last=False)
    return new


def _release_dropped() -> None:
    """Let go of the objects of scenes that only this table still holds.

    A live Mitsuba object is a Dr.Jit instance that every later trace's
    virtual calls go through (a render of one scene took 7x longer with five
    other scenes alive), so a scene the caller has dropped must not be kept;
    its token is never given again.
    """
    ours: dict = {}
    for objects, _ in _held.values():
        ours[id(objects[0])] = ours.get(id(objects[0]), 0) + 1
    for ids, (objects, _) in list(_held.items()):
        # references to the scene: ours and getrefcount's argument, nobody else's
        if sys.getrefcount(objects[0]) <= ours[id(objects[0])] + 1:
            del _held[ids]
