"""The host tables of the segment quadrature in ``cl/raytrace/quadrature.h`` (docs/raytracing.md §2):
where a segment is sampled, and the weights that integrate the polynomial through the samples."""

from __future__ import annotations

import numpy as np
from numpy.polynomial import chebyshev


def sample_points(degree: int) -> np.ndarray:
    """Where ``cl/raytrace/raytrace.cl`` samples a segment [-1, 1] whose polynomials have ``degree`` (at most 9):
    xi = -1 + p/4 for p = 1..8 (lanes 0..7), p = 0 (lane 8), and 15/16 when the degree is 9."""
    extra = [15 / 16] if degree == 9 else []
    return np.array([-1.0 + p / 4.0 for p in range(1, 9)] + [-1.0] + extra)


def sample_tables(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """``(nodes, weights)`` float64 for ``cl/raytrace/raytrace.cl``, from :func:`sample_points` xi_k.

    ``nodes``: the points, then the matrix taking the samples of a polynomial of the degree to
    its Chebyshev series (row m: coefficient m), then the (9, 9) one taking lanes 0..8 to the
    series of the gradient, whose degree is one less.  ``weights`` (points, 8): row k holds
    sample k's weight in the integral from -1 to xi = -1 + p/4, p = 1..8, of the polynomial
    through the samples (Simpson's first 2 panels and their halves need only these points, so
    the kernel makes the series only for finer panels).
    """
    xi = sample_points(degree)
    to_series = np.linalg.inv(chebyshev.chebvander(xi, len(xi) - 1))
    gradient_series = np.linalg.inv(chebyshev.chebvander(xi[:9], 8))
    ends = -1.0 + np.arange(1, 9) / 4.0
    weights = chebyshev.chebval(ends, chebyshev.chebint(to_series, lbnd=-1))  # (points, 8)
    nodes = np.concatenate([xi, to_series.ravel(), gradient_series.ravel()])
    return nodes, np.ascontiguousarray(weights)
