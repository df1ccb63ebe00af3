"""Sampling a film's reconstruction filter, so a traced pixel is mi.render's pixel.

``mi.render`` takes samples uniformly over every pixel and splats each one
into the pixels around it with the film's filter ``f`` (Mitsuba's default
``gaussian`` reaches two pixels): a pixel's expected value is the
filter-weighted mean of the radiance around its centre,
``∫ f(x - c) L(x) dx / ∫ f(x - c) dx``.  When the MRT traces every pixel it
does exactly that.  When it traces some pixels, each is estimated from its
own samples, placed around its centre with density proportional to ``|f|``
(a tabulated, separable distribution): weighted by ``f / density``, which
is the filter's sign, their mean has the same expectation, without the
neighbours' samples that a sparse grid does not have.  Samples outside the
image are dropped, as ``mi.render`` never takes them.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

#: Cells of the tabulated filter distribution over [-radius, radius].
TABLE_CELLS = 512
#: Bins of :meth:`FilterTable.guide` over [0, 1): a sample's cell is found
#: by bisecting the few cells its bin spans (one to six steps for Mitsuba's
#: filters), not all :data:`TABLE_CELLS`.
GUIDE_BINS = 4096


@dataclass(frozen=True)
class FilterTable:
    """The piecewise-constant distribution of ``|f|`` along one axis.

    Attributes
    ----------
    radius : float
        The filter's radius in pixels.
    cdf : ndarray, shape (TABLE_CELLS + 1,)
        Cumulative mass at the cell boundaries, 0 to 1.
    pdf : ndarray, shape (TABLE_CELLS,)
        Density (per pixel) in each cell.
    negative : bool
        Whether the filter is negative somewhere (a sample's weight is then -1 there).
    """

    radius: float
    cdf: np.ndarray
    pdf: np.ndarray
    negative: bool = False

    @property
    def cell(self) -> float:
        """Width of a cell in pixels."""
        return 2.0 * self.radius / (len(self.cdf) - 1)

    def sample(self, u: np.ndarray) -> np.ndarray:
        """Offsets from the pixel centre for uniform numbers ``u`` (numpy).

        Examples
        --------
        >>> t = FilterTable.from_values(0.5, np.ones(4))
        >>> t.sample(np.array([0.0, 0.5, 0.999])).round(3).tolist()
        [-0.5, 0.0, 0.499]
        """
        k = np.clip(np.searchsorted(self.cdf, u, side="right") - 1, 0, len(self.pdf) - 1)
        mass = self.cdf[k + 1] - self.cdf[k]
        inside = np.where(mass > 0, (u - self.cdf[k]) / np.where(mass > 0, mass, 1.0), 0.5)
        return -self.radius + (k + inside) * self.cell

    @property
    def uniform(self) -> bool:
        """Whether every cell has the same mass (a box filter): a cell's
        ``cdf[k]`` is then ``k / cells``, and ``u`` lies ``u * cells`` cells in."""
        return bool(np.all(self.pdf == self.pdf[0]))

    @functools.cached_property
    def guide(self) -> tuple[np.ndarray, int]:
        """A guide table for finding a uniform number's cell: (first, steps),
        made once per table.

        With ``bins`` = :data:`GUIDE_BINS`, ``first[j]`` is the cell of
        ``u = j / bins`` (the first ``k`` with
        ``cdf[k + 1] > u``, compared in float32 as a kernel compares them; the
        last cell where there is none); the cell of any ``u`` in
        ``[j / bins, (j + 1) / bins)`` is ``first[j]`` plus at most ``steps``
        (each a step past one more cell whose ``cdf[k + 1] <= u``): the cell
        a bisection of the whole table finds, for a few lookups.

        Examples
        --------
        >>> first, steps = FilterTable.from_values(0.5, np.ones(4)).guide
        >>> first[::GUIDE_BINS // 8].tolist(), steps
        ([0, 0, 1, 1, 2, 2, 3, 3, 3], 1)
        """
        cdf = np.asarray(self.cdf, dtype=np.float32)
        u = (np.arange(GUIDE_BINS + 1) / GUIDE_BINS).astype(np.float32)
        first = np.minimum(np.searchsorted(cdf[1:], u, side="right"), len(self.pdf) - 1)
        return first.astype(np.uint32), int(np.diff(first).max(initial=0))

    @classmethod
    def from_values(cls, radius: float, values: np.ndarray) -> "FilterTable":
        """The table of filter values at the cell centres."""
        values = np.asarray(values, dtype=np.float64)
        mass = np.abs(values)
        if not mass.sum() > 0:
            mass = np.ones_like(mass)
        cdf = np.concatenate([[0.0], np.cumsum(mass)]) / mass.sum()
        cdf[-1] = 1.0
        pdf = (mass / mass.sum()) / (2.0 * radius / len(mass))
        return cls(float(radius), cdf, pdf, bool((values < 0).any()))


def filter_reach(radius: float) -> int:
    """How many pixels beyond its own (Chebyshev) a pixel's samples land in,
    for a filter of ``radius`` pixels: those within ``radius`` of its centre.

    Examples
    --------
    >>> [filter_reach(r) for r in (0.5, 1.0, 1.5, 2.0, 3.0)]  # box, tent, ..., gaussian, lanczos
    [0, 1, 1, 2, 3]
    """
    return max(int(np.ceil(radius - 0.5 - 1e-9)), 0)


#: Tables already made, by the filter's description (its type and parameters).
_TABLES: dict[str, FilterTable] = {}


def filter_table(rfilter) -> FilterTable:
    """The :class:`FilterTable` of a Mitsuba reconstruction filter."""
    key = str(rfilter)
    if key not in _TABLES:
        radius = float(rfilter.radius())
        centres = -radius + (np.arange(TABLE_CELLS) + 0.5) * (2.0 * radius / TABLE_CELLS)
        values = [np.asarray(rfilter.eval(float(x))).ravel()[0] for x in centres]
        _TABLES[key] = FilterTable.from_values(radius, np.array(values))
    return _TABLES[key]
