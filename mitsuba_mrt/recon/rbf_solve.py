"""Solving the linear RBF system fast: float32 Cholesky plus float64 refinement.

The system of :class:`mitsuba_mrt.recon.rbf.LinearRBF` is

    [A  P] [w]   [f]
    [P' 0] [c] = [0]        A_ij = |c_i - c_j|,  P the polynomial part,

or ``A w = f`` alone for the report's RBF (no polynomial).  ``A`` is
indefinite, so the textbook solvers are a symmetric-indefinite or an LU
factorisation in float64.  But ``|r|`` is conditionally negative definite:
on the vectors orthogonal to the constants (to the columns of ``P``), ``-A``
is positive definite.  So, with ``Q = [Q1 Q2]`` the Householder basis of
``P`` (of the constants when there is no polynomial), ``-Q2' A Q2`` has a
Cholesky factor, and the rest of the system is a few small dense products.

That factor is computed in float32, half the time of float64 on the same
cores, and used as an approximate inverse inside iterative refinement whose
residuals are float64 products with ``A``: the refinement stops at a residual
of ``TOLERANCE`` relative to the data, far below the float32 resolution of
the image the interpolant fills.
Each refinement step divides the residual by roughly ``1 / (cond * 6e-8)``;
a system too ill-conditioned for that, or one whose float32 factor fails, is
solved by float64 LU instead, so the answer never depends on the shortcut.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg
from scipy.linalg import blas, lapack
from scipy.spatial.distance import cdist

from ..runtime.threads import for_row_blocks

#: Systems smaller than this are solved by float64 LU directly.
MIN_SIZE = 128
#: Refinement stops when the largest residual is this fraction of the data's
#: largest magnitude: a sixtieth of float32's rounding (6e-8), which the
#: image is stored in (float64 LU reaches about 1e-14 on these systems, two
#: or three more refinement steps).
TOLERANCE = 1e-9
#: Most refinement steps before falling back to float64 LU.
MAX_STEPS = 30
#: Distance triangles with at least this many rows are computed on all cores.
PARALLEL_ROWS = 512
#: Bytes per pair of centres that a solve holds: ``A`` in float64 and its
#: negation in float32 (:func:`distance_triangles`; float64 LU, the rare
#: fallback, holds several float64 copies more).
BYTES_PER_PAIR = 12
#: Rows of the distance triangle per ``cdist`` call (a block stays in cache
#: while it is copied and negated).
CHUNK_ROWS = 64


def solve_linear_rbf_at(centres: np.ndarray, poly: np.ndarray,
                        values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`solve_linear_rbf` for ``A_ij = |centres_i - centres_j|``, (n, d) centres.

    Computes only what the solver reads: for the float32-Cholesky path the
    upper triangles of ``A`` and ``-A`` (:func:`distance_triangles`), for
    float64 LU the whole matrix.  The answer is the same, bit for bit.

    Examples
    --------
    >>> c = np.arange(200.0)[:, None]
    >>> w, p = solve_linear_rbf_at(c, np.ones((200, 1)), c.copy())
    >>> bool(np.allclose(np.abs(c - c.T) @ w + p, c))
    True
    """
    centres = np.ascontiguousarray(centres, dtype=np.float64)
    n, m = poly.shape
    if n >= MIN_SIZE and n > m + 1:
        distances, negated = distance_triangles(centres)
        solved = _refined_cholesky(distances, poly, values, negated)
        if solved is not None:
            return solved
        upper = np.triu(distances)
        return _lu(upper + np.triu(distances, 1).T, poly, values)
    return _lu(cdist(centres, centres), poly, values)


def distance_triangles(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Upper triangles (``j >= i``) of ``|p_i - p_j|`` in float64 and of its
    negation in float32, the rest of both (n, n) arrays left unset.

    The upper triangle of a C-ordered array is the lower triangle of its
    Fortran view, the only part that :func:`_refined_cholesky`'s BLAS and
    LAPACK calls read; it is half the work of ``cdist``, and the negation is
    made while each block is in cache, on all cores.

    Examples
    --------
    >>> d, neg = distance_triangles(np.array([[0.0, 0.0], [3.0, 4.0]]))
    >>> float(d[0, 1]), float(neg[0, 1]), float(d[1, 1])
    (5.0, -5.0, 0.0)
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    n = len(points)
    distances = np.empty((n, n))
    negated = np.empty((n, n), dtype=np.float32)

    def rows(start, stop):
        for lo in range(start, stop, CHUNK_ROWS):
            hi = min(lo + CHUNK_ROWS, stop)
            block = cdist(points[lo:hi], points[lo:])
            distances[lo:hi, lo:] = block
            np.negative(block, out=negated[lo:hi, lo:], casting="same_kind")

    for_row_blocks(rows, n, PARALLEL_ROWS, upper_triangle=True)
    return distances, negated


def solve_linear_rbf(distances: np.ndarray, poly: np.ndarray,
                     values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weights ``w`` (n, k) and polynomial coefficients ``c`` (m, k) of the system above.

    Parameters
    ----------
    distances : ndarray, shape (n, n)
        The symmetric matrix ``A`` (float64).
    poly : ndarray, shape (n, m)
        The polynomial part ``P``, full column rank (m = 0: none).
    values : ndarray, shape (n, k)
        The data ``f``.

    Raises
    ------
    numpy.linalg.LinAlgError
        If the system is singular (repeated centres).

    Examples
    --------
    >>> c = np.arange(200.0)[:, None]
    >>> w, p = solve_linear_rbf(np.abs(c - c.T), np.ones((200, 1)), c.copy())
    >>> bool(np.allclose(np.abs(c - c.T) @ w + p, c))
    True
    """
    n, m = poly.shape
    if n >= MIN_SIZE and n > m + 1:
        solved = _refined_cholesky(distances, poly, values)
        if solved is not None:
            return solved
    return _lu(distances, poly, values)


def _lu(distances, poly, values):
    """Float64 LU of the whole system (scipy's ``solve``)."""
    n, m = poly.shape
    system = np.zeros((n + m, n + m))
    system[:n, :n] = distances
    system[:n, n:] = poly
    system[n:, :n] = poly.T
    rhs = np.zeros((n + m, values.shape[1]))
    rhs[:n] = values
    coeffs = scipy.linalg.solve(system, rhs)
    return coeffs[:n], coeffs[n:]


def _householder(columns: np.ndarray) -> tuple[list, np.ndarray]:
    """Unit Householder vectors ``v`` (``H = I - 2 v v'``) with ``H_{m-1}..H_0 Y = [R; 0]``, and ``R``."""
    y = np.array(columns, dtype=np.float64)
    n, m = y.shape
    vectors = []
    for j in range(m):
        x = y[j:, j]
        v = np.zeros(n)
        v[j:] = x
        v[j] += np.copysign(np.linalg.norm(x), x[0])
        v /= np.linalg.norm(v)
        vectors.append(v)
        y -= 2.0 * np.outer(v, v @ y)
    return vectors, y[:m]


def _reflect(vectors, x: np.ndarray, transpose: bool) -> np.ndarray:
    """``Q' x`` (transpose) or ``Q x`` for ``Q = H_0 .. H_{m-1}``."""
    x = np.array(x, dtype=np.float64)
    for v in (vectors if transpose else vectors[::-1]):
        x -= 2.0 * np.outer(v, v @ x)
    return x


def _refined_cholesky(distances, poly, values, negated=None):
    """The float32-factor, float64-refined solve; None when it cannot be trusted.

    Only the upper triangles (C order) of ``distances`` and of ``negated``
    (float32 ``-distances``, computed here when not given; overwritten) are read.
    """
    n, m = poly.shape
    k = values.shape[1]
    vectors, r_factor = _householder(poly if m else np.ones((n, 1)))
    q = len(vectors)  # columns of Q1: m, or 1 (the constants) without a polynomial

    # -Q' A Q in float32, one triangle: symmetric rank-2 updates, one per reflector.
    # A is symmetric, so its C-ordered transpose is the Fortran array BLAS wants.
    if negated is None:
        negated = np.negative(distances, dtype=np.float32)
    negated = negated.T
    for v in vectors:
        v32 = v.astype(np.float32)
        y = blas.ssymv(1.0, negated, v32, lower=1).astype(np.float64)
        z = 2.0 * y - 2.0 * (v @ y) * v  # H M H = M - v z' - z v'
        negated = blas.ssyr2(-1.0, v32, z.astype(np.float32), a=negated, lower=1, overwrite_a=1)
    # Factor -Q2' A Q2 in place: an identity on the first q rows and columns
    # makes the whole matrix block diagonal, which spares copying out the block.
    negated[:q] = 0.0
    negated[:, :q] = 0.0
    negated[range(q), range(q)] = 1.0
    factor, info = lapack.spotrf(negated, lower=1, overwrite_a=1, clean=0)
    if info != 0:  # not positive definite in float32: singular or too ill-conditioned
        return None

    def solve_s(rhs):  # S^-1 rhs for S = Q2' A Q2 (negative definite); columns one by one
        out = np.empty(rhs.shape)
        padded = np.zeros(n, dtype=np.float32)
        for j in range(rhs.shape[1]):
            padded[q:] = rhs[:, j]
            half = blas.strsv(factor, padded, lower=1)
            out[:, j] = blas.strsv(factor, half, lower=1, trans=1)[q:]
        return -out

    # A x column by column: symv (half the matrix read; several times faster than
    # gemm for a few columns), from scipy's BLAS, whose threads are the ones still
    # spinning after spotrf (numpy's own would start a second pool on the same cores)
    distances_f = distances.T  # Fortran view of the symmetric matrix: no copy

    def product(x):
        return np.stack([blas.dsymv(1.0, distances_f, x[:, j], lower=1)
                         for j in range(x.shape[1])], axis=1)

    a_q1 = product(_reflect(vectors, np.eye(n, q), transpose=False))  # A Q1, float64
    if m == 0:
        # A w = f with w = Q1 alpha + Q2 u: a Schur complement on the one constant direction
        qt_a_q1 = _reflect(vectors, a_q1, transpose=True)[:, 0]
        a11, b = qt_a_q1[0], qt_a_q1[1:, None]
        h = solve_s(b)
        schur = a11 - float(b[:, 0] @ h[:, 0])

        def approximate(res_f, res_g):
            t = _reflect(vectors, res_f, transpose=True)
            s2 = solve_s(t[1:])
            alpha = (t[0] - b[:, 0] @ s2) / schur
            return _reflect(vectors, np.vstack([alpha[None], s2 - h * alpha]), False), res_g
    else:
        def approximate(res_f, res_g):
            # P' w = g fixes the Q1 part; Q2' (A w + P c) = Q2' f the rest; Q1' (...) gives c
            a = scipy.linalg.solve_triangular(r_factor, res_g, trans="T")
            t = _reflect(vectors, res_f - a_q1 @ a, transpose=True)
            w = _reflect(vectors, np.vstack([a, solve_s(t[q:])]), transpose=False)
            c = scipy.linalg.solve_triangular(
                r_factor, _reflect(vectors, res_f, transpose=True)[:q] - a_q1.T @ w)
            return w, c

    # Refine each column until its residual is TOLERANCE of the data's largest
    # value.  Columns are first made small where they can be: the others minus
    # their projection on the largest (colour channels are often nearly equal),
    # so they converge in a step or two and leave the loop.
    values = values.astype(np.float64)
    scale = float(np.abs(values).max())
    if scale == 0.0 or not np.isfinite(scale):
        return (np.zeros((n, k)), np.zeros((m, k))) if scale == 0.0 else None
    # Refine values divided by a power of two near their largest magnitude
    # (exact): data near float64's or float32's largest finite value would
    # overflow in the products below (the float32 solves see the residuals).
    unit = math.ldexp(1.0, math.frexp(scale)[1])
    try:
        solved = _refine(approximate, product, poly, values / unit, scale / unit)
    except ValueError:  # NaN or Inf reached scipy after all: not to be trusted
        return None
    return None if solved is None else (solved[0] * unit, solved[1] * unit)


def _refine(approximate, product, poly, values, scale):
    """Iterative refinement of ``A w + P c = values, P' w = 0`` with the
    approximate solver ``approximate(res_f, res_g) -> (dw, dc)``; None when
    it stalls above ``TOLERANCE`` or diverges."""
    n, m = poly.shape
    k = values.shape[1]
    lead = int(np.argmax(np.abs(values).max(axis=0)))
    share = values[:, lead] @ values / (values[:, lead] @ values[:, lead])
    share[lead] = 0.0
    data = values - np.outer(values[:, lead], share)
    weights, coeffs = np.zeros((n, k)), np.zeros((m, k))
    res_f, res_g = data.copy(), np.zeros((m, k))
    active = np.arange(k)
    previous = np.full(k, np.inf)
    for _ in range(MAX_STEPS):
        dw, dc = approximate(res_f[:, active], res_g[:, active])
        weights[:, active] += dw
        coeffs[:, active] += dc
        res_f[:, active] = data[:, active] - product(weights[:, active]) - poly @ coeffs[:, active]
        res_g[:, active] = -(poly.T @ weights[:, active])
        residual = np.maximum(np.abs(res_f[:, active]).max(axis=0),
                              np.abs(res_g[:, active]).max(axis=0, initial=0.0)) / scale
        if not np.isfinite(residual).all():
            return None
        going = residual > TOLERANCE
        if (going & (residual > 0.5 * previous[active])).any():  # stalled or diverging
            return None
        previous[active] = residual
        active = active[going]
        if len(active) == 0:
            # back to the original columns: solution of f_j = data_j + share_j f_lead
            return (weights + np.outer(weights[:, lead], share),
                    coeffs + np.outer(coeffs[:, lead], share))
    return None
