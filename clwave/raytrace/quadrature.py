"""The host tables of the segment quadrature in ``cl/raytrace/quadrature.h`` (docs/raytracing.md §2):
where a segment is sampled, and the weights that integrate the polynomial through the samples."""

from __future__ import annotations

import functools

import numpy as np
from numpy.polynomial import chebyshev

#: the points past the quarter points, by the pieces' degree (order j: 3 (j - 1)).  Degree 15 (order 6): seven
#: points in 32nds chosen so that the 16 points' Lebesgue constant is 36 and that of the first 15 (alpha's
#: gradient, degree 14) is 17 (the odd eighths but 1/8 would give 234 and 2364; docs/raytracing.md §2)
EXTRA_POINTS = {9: (15 / 16,), 15: tuple(k / 32 for k in (-30, -23, -13, 14, 29, 31, -3))}
DEGREES = (0, 3, 6, 9, 15)  # of orders 1, 2, 3, 4 and 6


def sample_points(degree: int) -> np.ndarray:
    """Where ``cl/raytrace/raytrace.cl`` samples a segment [-1, 1] whose polynomials have ``degree`` (9 at most,
    or 15): xi = -1 + p/4 for p = 1..8 (lanes 0..7), p = 0 (lane 8), then :data:`EXTRA_POINTS` (lanes 9..)."""
    if degree not in DEGREES:
        raise ValueError(f"segment polynomials of degree {degree}: the kernels take degrees {DEGREES}")
    return np.array([-1.0 + p / 4.0 for p in range(1, 9)] + [-1.0] + list(EXTRA_POINTS.get(degree, ())))


def gradient_samples(n_samples: int) -> int:
    """How many lanes (0..n-1) give alpha's gradient series: 9 (degree 8 at most), or 15 with 16 samples
    (degree 14); ``NG`` in ``cl/raytrace/types.h``."""
    return n_samples - 1 if n_samples > 10 else 9


def sample_tables(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """``(nodes, weights)`` float64 for ``cl/raytrace/raytrace.cl``, from :func:`sample_points` xi_k.

    ``nodes``: the points, then the matrix taking the samples of a polynomial of the degree to
    its Chebyshev series (row m: coefficient m), then the (NG, NG) one taking lanes 0..NG-1 to the
    series of the gradient, whose degree is one less (:func:`gradient_samples`).  ``weights`` (points, 8):
    row k holds sample k's weight in the integral from -1 to xi = -1 + p/4, p = 1..8, of the polynomial
    through the samples (Simpson's first 2 panels and their halves need only these points, so
    the kernel makes the series only for finer panels).
    """
    xi = sample_points(degree)
    ng = gradient_samples(len(xi))
    to_series = np.linalg.inv(chebyshev.chebvander(xi, len(xi) - 1))
    gradient_series = np.linalg.inv(chebyshev.chebvander(xi[:ng], ng - 1))
    ends = -1.0 + np.arange(1, 9) / 4.0
    weights = chebyshev.chebval(ends, chebyshev.chebint(to_series, lbnd=-1))  # (points, 8)
    nodes = np.concatenate([xi, to_series.ravel(), gradient_series.ravel()])
    return nodes, np.ascontiguousarray(weights)


#: bins of the knot's position xi_c in [-1, 1] in :func:`span_table`
SPAN_BINS = 32


def span_errors(degree: int, xi_c: float) -> np.ndarray:
    """``(2 (j - 1) + 1,)``: for m = 0.., the largest error over the rows of :func:`sample_tables`' weights (the
    integrals from -1 to xi = -1 + p/4) on the truncated power ``(xi - xi_c)^(j - 1 + m)_+`` of a segment crossing
    one knot plane at ``xi_c`` (order j = degree / 3 + 1; docs/raytracing.md §12)."""
    xi = sample_points(degree)
    _, weights = sample_tables(degree)
    ends = -1.0 + np.arange(1, 9) / 4.0
    n = degree // 3 + np.arange(2 * (degree // 3) + 1)  # the powers j - 1 + m
    rule = (np.where(xi > xi_c, xi - xi_c, 0.0)[None, :] ** n[:, None]) @ weights  # (m, rows)
    exact = np.where(ends > xi_c, ends - xi_c, 0.0)[None, :] ** (n[:, None] + 1) / (n[:, None] + 1)
    return np.abs(rule - exact).max(axis=1)


@functools.cache
def span_table(degree: int) -> np.ndarray:
    """``(SPAN_BINS, 8)`` float64: row b, column m, the largest of :func:`span_errors` over the knot positions
    xi_c of bin b (``[-1 + 2b/SPAN_BINS, -1 + 2(b + 1)/SPAN_BINS]``), exact: between the sample points and the
    rows' ends each error is a polynomial in xi_c, whose largest magnitude is at an end or a root of its
    derivative (plus 1e-11 for the rounding of the expanded powers in float64).  The kernel's bound on a segment
    across a knot plane (``span_cost`` in ``cl/raytrace/quadrature.h``, :func:`span_bound`) reads it."""
    xi = sample_points(degree)
    _, weights = sample_tables(degree)
    ends = -1.0 + np.arange(1, 9) / 4.0
    powers = degree // 3 + np.arange(2 * (degree // 3) + 1)
    edges = np.linspace(-1.0, 1.0, SPAN_BINS + 1)
    breaks = np.unique(np.concatenate([xi, ends, edges]))
    table = np.zeros((SPAN_BINS, 8))
    P = np.polynomial.Polynomial
    for lo, hi in zip(breaks[:-1], breaks[1:]):
        mid = (lo + hi) / 2
        worst = np.zeros(len(powers))
        for i, n in enumerate(powers):
            for p in range(8):  # the rule's error as a polynomial in xi_c on (lo, hi)
                err = sum((weights[k, p] * P([x, -1.0]) ** n for k, x in enumerate(xi) if x > mid), P([0.0]))
                if ends[p] > mid:
                    err = err - P([ends[p], -1.0]) ** (n + 1) / (n + 1)
                roots = err.deriv().roots()
                at = np.concatenate([[lo, hi], roots.real[(abs(roots.imag) < 1e-12) & (roots.real > lo)
                                                          & (roots.real < hi)]])
                worst[i] = max(worst[i], np.abs(err(at)).max())
        first, last = np.searchsorted(edges, lo, "right") - 1, np.searchsorted(edges, hi, "left") - 1
        rows = slice(max(first, 0), min(last, SPAN_BINS - 1) + 1)
        table[rows, : len(powers)] = np.maximum(table[rows, : len(powers)], worst + 1e-11)
    return table


def span_bound(table: np.ndarray, degree: int, xi_c: float, slope: float, sigma: float, jump: float) -> float:
    """The bound on the error of every row of the weights (alpha's integral from -1 to the quarter points, in xi)
    on a segment across one knot plane at ``xi_c``, where the field gains
    ``(slope (xi - xi_c))^(j-1)_+ / (j-1)! J(xi)``: ``slope`` lattice cells per unit xi along the crossed axis,
    ``sigma`` the sum of those along the other two, ``jump`` the largest |j-th difference| of the coefficients
    across the plane (docs/raytracing.md §12; the kernel's ``span_cost``)."""
    k = degree // 3
    b = min(max(int((xi_c + 1) * SPAN_BINS / 2), 0), SPAN_BINS - 1)
    taylor = sum((2 * sigma) ** m / np.prod(np.arange(1, m + 1)) * table[b, m] for m in range(2 * k + 1))
    return abs(slope) ** k / np.prod(np.arange(1, k + 1)) * jump * taylor
