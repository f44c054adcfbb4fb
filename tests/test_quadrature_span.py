"""Segments across one knot plane (docs/raytracing.md §12): the bound on the quadrature's error there, against exact
integrals of random cubic B-spline fields along random rays (float64, NumPy only)."""

import numpy as np
import pytest

from clwave.raytrace.quadrature import sample_points, sample_tables, span_bound, span_table


def cubic_bspline(x):
    """The cubic B-spline on [0, 4) (knots at the integers), closed form."""
    x = np.asarray(x, float)
    out = np.zeros_like(x)
    for lo, piece in ((0, lambda u: u ** 3 / 6), (1, lambda u: (-3 * u ** 3 + 3 * u ** 2 + 3 * u + 1) / 6),
                      (2, lambda u: (3 * u ** 3 - 6 * u ** 2 + 4) / 6), (3, lambda u: (1 - u) ** 3 / 6)):
        inside = (x >= lo) & (x < lo + 1)
        out[inside] = piece(x[inside] - lo)
    return out


def field(c, points):
    """sum_i c_i N(x - i) N(y - i_y) N(z - i_z) at (n, 3) points, by brute force over every coefficient."""
    idx = np.arange(c.shape[0])
    w = [cubic_bspline(points[:, a, None] - idx[None, :]) for a in range(3)]  # (n, size) per axis
    return np.einsum("ni,nj,nk,ijk->n", w[0], w[1], w[2], c)


def one_crossing(rng, size):
    """A random ray segment inside the lattice's interior that crosses exactly one knot plane: its start, direction
    and half length, and that plane's axis."""
    while True:
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        x0 = rng.uniform(4.2, size - 1.2, 3)
        t = {a: (np.floor(x0[a]) + (d[a] > 0) - x0[a]) / d[a] for a in range(3)}
        order = sorted(t, key=t.get)
        tn = min(t[order[1]], rng.uniform(t[order[0]], 2 * t[order[1]]))  # past the first plane, not the second
        end = x0 + tn * d
        if t[order[0]] < tn and np.all((end > 4.1) & (end < size - 1.1)):
            return x0, d, tn / 2, order[0], t[order[0]]


@pytest.mark.parametrize("smooth", [False, True])
def test_span_bound_holds_for_random_fields_and_rays(smooth):
    """Every row of the weights (alpha's integral from -1 to a quarter point) on the exact samples of a segment
    across one knot plane errs by at most :func:`span_bound`, computed from the largest 4th difference of the
    coefficients across the plane; the exact integrals are Gauss-Legendre on each polynomial piece.  Over random
    fields (white noise, and a smooth one) and rays the bound is reached within a factor 20 somewhere."""
    rng = np.random.default_rng(7 + smooth)
    size = 12
    c = rng.random((size, size, size))
    if smooth:  # a slowly varying field: small 4th differences
        g = np.arange(size)
        c = np.sin(0.3 * g)[:, None, None] * np.cos(0.25 * g)[None, :, None] + 0.02 * g[None, None, :] + c * 1e-3
    xi = sample_points(9)
    _, weights = sample_tables(9)
    table = span_table(9)
    ends = -1.0 + np.arange(1, 9) / 4.0
    gl, glw = np.polynomial.legendre.leggauss(10)
    ratios = []
    for _ in range(40):
        x0, d, r, axis, tc = one_crossing(rng, size)
        mid = x0 + r * d
        xi_c = tc / r - 1
        values = field(c, mid + r * xi[:, None] * d)
        got = values @ weights

        def integral(lo, hi):  # exact: the field is one polynomial of degree 9 on each side of the plane
            if hi <= lo:
                return 0.0
            pts = (hi - lo) / 2 * gl + (hi + lo) / 2
            return (hi - lo) / 2 * glw @ field(c, mid + r * pts[:, None] * d)

        exact = np.array([integral(-1, min(e, xi_c)) + integral(xi_c, e) for e in ends])
        # the coefficients across the plane: 5 along the axis crossed, the 4 of each other axis' cell
        K = int(round((x0 + tc * d)[axis]))
        box = [slice(int(np.floor(mid[a])) - 3, int(np.floor(mid[a])) + 1) for a in range(3)]
        box[axis] = slice(K - 4, K + 1)
        jump = np.abs(np.diff(c[tuple(box)], 4, axis=axis)).max()
        others = [a for a in range(3) if a != axis]
        bound = span_bound(table, 9, xi_c, r * d[axis], r * np.abs(d[others]).sum(), jump)
        err = np.abs(got - exact).max()
        assert err <= bound * (1 + 1e-9) + 1e-13
        ratios.append(err / bound)
    assert max(ratios) > 0.05


def test_span_table_is_the_largest_error_of_each_bin():
    """Each bin's entry bounds the rows' errors at every knot position in it (dense sampling) and is reached there
    (within 2 %, or the 1e-11 rounding floor)."""
    from clwave.raytrace.quadrature import SPAN_BINS, span_errors

    table = span_table(9)
    for b in range(SPAN_BINS):
        errors = np.max([span_errors(9, x) for x in np.linspace(-1 + 2 * b / SPAN_BINS, -1 + 2 * (b + 1) / SPAN_BINS,
                                                                  41)], axis=0)
        assert np.all(errors <= table[b, :7])
        assert np.all(errors >= 0.98 * table[b, :7] - 2e-11)
