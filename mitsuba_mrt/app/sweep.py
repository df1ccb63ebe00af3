"""The ``-D`` values of a batch: the value syntax and the combinations.

A ``-D name=VALUES`` gives one value, a comma list or a range
``start:stop:step`` (:func:`parse_values`); a :class:`Sweep` is every
``-D`` of a batch, and its :meth:`~Sweep.combinations` are the cartesian
product that :func:`mitsuba_mrt.app.tasks.plan_tasks` makes a task of each.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

from ..errors import MRTError

#: Most tasks one batch may plan (a typo in a range should not plan millions).
MAX_TASKS = 100_000


def _number(text: str) -> int | float | None:
    try:
        return int(text)
    except ValueError:
        pass
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _format(value: float) -> str:
    text = f"{value:.12g}"
    return "0" if text == "-0" else text


def _range(text: str, where: str) -> list[str]:
    parts = text.split(":")
    if len(parts) not in (2, 3):
        raise MRTError(f"{where}: a range is start:stop:step, got {text!r}")
    numbers = [_number(p.strip()) for p in parts]
    if any(n is None for n in numbers):
        raise MRTError(f"{where}: a range start:stop:step needs numbers, got {text!r}")
    start, stop, step = numbers if len(numbers) == 3 else (*numbers, 1)
    if step == 0:
        raise MRTError(f"{where}: the step of a range cannot be 0")
    if all(isinstance(n, int) for n in (start, stop, step)):
        count = len(range(start, stop, step))
        values = [str(v) for v in itertools.islice(range(start, stop, step), MAX_TASKS + 1)]
    else:
        # stop is exclusive, as in range(); a stop that rounding puts a hair
        # above the last value is not a value
        q = (stop - start) / step
        count = max(0, math.ceil(q - 1e-9 * max(1.0, abs(q))))
        values = [_format(start + i * step) for i in range(min(count, MAX_TASKS + 1))]
    if count == 0:
        raise MRTError(f"{where}: the range {text} is empty (stop is exclusive)")
    if count > MAX_TASKS:
        raise MRTError(f"{where}: the range {text} has {count} values, more than {MAX_TASKS}")
    return values


def parse_values(text: str, name: str = "value") -> list[str]:
    """The values of one ``-D name=VALUES``, as the strings Mitsuba is given.

    ``VALUES`` is one value, a comma list, or a range ``start:stop:step``
    (stop exclusive, as Python's ``range``; ``start:stop`` steps by 1;
    floats allowed); a comma list may hold ranges.  Bad input raises a
    one-line :class:`MRTError` naming the define.

    Examples
    --------
    >>> parse_values("16")
    ['16']
    >>> parse_values("path,matte")
    ['path', 'matte']
    >>> parse_values("0:360:90")
    ['0', '90', '180', '270']
    >>> parse_values("0:1:0.25")
    ['0', '0.25', '0.5', '0.75']
    >>> parse_values("0:0.3:0.1")
    ['0', '0.1', '0.2']
    >>> parse_values("0:60:30,90")
    ['0', '30', '90']
    """
    where = f"-D {name}={text}"
    items = text.split(",") if "," in text else [text]
    values: list[str] = []
    for item in items:
        item = item.strip()
        if not item and len(items) > 1:
            raise MRTError(f"{where}: empty value in a comma list")
        values += _range(item, where) if ":" in item else [item]
    twice = sorted({v for v in values if values.count(v) > 1})
    if twice:
        raise MRTError(f"{where}: the value {twice[0]!r} is given twice")
    return values


@dataclass(frozen=True)
class Sweep:
    """The ``-D`` options of a batch: each name with its values, in order.

    Examples
    --------
    >>> s = Sweep.parse([("res", "16"), ("azimuth", "0:90:30"), ("spp", "1,4")])
    >>> s.varying
    ('azimuth', 'spp')
    >>> len(s.combinations()), s.combinations()[1]
    (6, {'res': '16', 'azimuth': '0', 'spp': '4'})
    """

    names: tuple[str, ...] = ()
    values: tuple[tuple[str, ...], ...] = ()

    @classmethod
    def parse(cls, defines) -> "Sweep":
        """From ``(name, VALUES)`` pairs (the command line's ``-D``)."""
        names, values = [], []
        for name, text in defines:
            if name in names:
                raise MRTError(f"-D {name} is given twice; put its values in one comma list")
            names.append(name)
            values.append(tuple(parse_values(text, name)))
        sweep = cls(tuple(names), tuple(values))
        count = math.prod(len(v) for v in sweep.values)
        if count > MAX_TASKS:
            raise MRTError(f"the -D values make {count} combinations, more than {MAX_TASKS}")
        return sweep

    @property
    def varying(self) -> tuple[str, ...]:
        """The names given more than one value: they name the task folders."""
        return tuple(n for n, v in zip(self.names, self.values) if len(v) > 1)

    def combinations(self) -> list[dict[str, str]]:
        """Every combination (the cartesian product, the first ``-D`` outermost)."""
        return [dict(zip(self.names, combo)) for combo in itertools.product(*self.values)]
