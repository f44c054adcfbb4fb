"""The host tables of the segment quadrature in ``cl/raytrace/quadrature.h`` (docs/raytracing.md §2):
where a segment is sampled, and the weights that integrate the polynomial through the samples."""

from __future__ import annotations

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
