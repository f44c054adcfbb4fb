"""Exact footprint samples (docs/splatting.md §1, the ``"spatial"`` path): the line integral of
a basis function, cut at its knot planes into segments where the integrand is one polynomial,
each integrated exactly.  Also the independent answer the FFT textures are tested against."""

from __future__ import annotations

from math import ceil, comb

import numpy as np

from ..model.bspline import eval_pieces, knots, pieces, wavelet_for
from ..model.geometry import check_key, orthonormal_frame, spacing_xyz


def _gauss_points(order: int) -> int:
    """Gauss-Legendre nodes exact for the product of three degree-(j-1) pieces."""
    return max(1, ceil((3 * (order - 1) + 1) / 2))


def _local_poly(coeffs, pidx, y, slope) -> list:
    """Taylor coefficients in tau of ``piece(y + slope tau)`` (``coeffs`` rows in y powers)."""
    deg = coeffs.shape[1] - 1
    cols = [np.take(coeffs[:, c], pidx) for c in range(deg + 1)]
    if deg == 1:  # linear pieces
        slope_col = cols[1] * slope
        cols[1] *= y
        cols[1] += cols[0]
        return [cols[1], slope_col]
    out = []
    for r in range(deg + 1):  # r-th derivative / r! at y, times slope^r
        acc = cols[deg] * comb(deg, r)
        for c in range(deg - 1, r - 1, -1):
            acc *= y
            acc += cols[c] * comb(c, r)
        out.append(acc * slope ** r if r else acc)
    return out


def _segment_integrals(taylor, half, order) -> np.ndarray:
    """``∫_{-h}^{h} prod_a sum_c taylor[a][c] tau^c dtau`` per segment (h = half)."""
    if order == 1:  # piecewise constants
        val = 2.0 * half
        for (p0,) in taylor:
            val = val * p0
        return val
    if order == 2 and len(taylor) <= 3:  # products of linears: only even powers survive
        A = [p[0] for p in taylor]
        B = [p[1] for p in taylor]
        if len(taylor) == 1:
            return 2.0 * half * A[0]
        h2 = half * half / 3.0
        if len(taylor) == 2:
            return 2.0 * half * (A[0] * A[1] + h2 * B[0] * B[1])
        even = A[0] * A[1] * A[2] + h2 * (A[0] * B[1] * B[2] + B[0] * A[1] * B[2] + B[0] * B[1] * A[2])
        return 2.0 * half * even
    x_g, w_g = np.polynomial.legendre.leggauss(_gauss_points(order))
    total = 0.0
    for xg, wg in zip(x_g, w_g):  # Gauss-Legendre, exact for the degree-3(j-1) product
        tau = half * xg
        prod = None
        for p in taylor:
            val = p[-1].copy()
            for c in p[-2::-1]:
                val *= tau
                val += c
            prod = val if prod is None else np.multiply(prod, val, out=prod)
        total = total + wg * prod
    return total * half


def exact_samples(wav, key, m, d_xyz, n, u, v, a, b, chunk=4096) -> np.ndarray:
    """Exact T at the offsets a, b (1-D float64 arrays of one length)."""
    j = wav.order
    key_xyz = key[::-1]
    out = np.zeros(a.size)
    scale = 2.0 ** (-m)
    for start in range(0, a.size, chunk):
        aa, bb = a[start:start + chunk], b[start:start + chunk]
        total = np.full(aa.size, 2.0 ** (-1.5 * m))
        lo = np.full(aa.size, -np.inf)
        hi = np.full(aa.size, np.inf)
        moving = []
        for ax in range(3):
            letter, support = key_xyz[ax], wav.support(key_xyz[ax])
            c = scale * (aa * u[ax] + bb * v[ax]) / d_xyz[ax] + support / 2.0  # prototype coordinate at t = 0
            g = scale * n[ax] / d_xyz[ax]                                       # ... and its rate along t
            if g == 0.0:  # the line runs along the axis' knot planes: a constant factor
                total *= eval_pieces(j, letter, c)
                continue
            # the line is inside the axis' support for t between (0 - c)/g and (S - c)/g
            t0, t1 = -c / g, (support - c) / g
            np.maximum(lo, np.minimum(t0, t1), out=lo)
            np.minimum(hi, np.maximum(t0, t1), out=hi)
            moving.append((letter, c, g))
        live = np.flatnonzero((hi > lo) & (total != 0.0))  # lines that meet the support box
        if not live.size:
            continue
        # every knot crossing t = (knot - c)/g, clipped to the support interval and sorted
        lo, hi = lo[live, None], hi[live, None]
        moving = [(letter, c[live], g) for letter, c, g in moving]
        t = np.concatenate([np.subtract.outer(c / -g, knots(j, letter) / -g) for letter, c, g in moving], axis=1)
        np.maximum(t, lo, out=t)
        np.minimum(t, hi, out=t)
        t.sort(axis=1)
        width = np.diff(t, axis=1)
        flat = np.flatnonzero(width > 0.0)           # the segments of positive length
        seg_line = flat // width.shape[1]
        half = 0.5 * width.reshape(-1)[flat]
        mid = t.reshape(-1)[flat + seg_line] + half   # left end + half width (t has one column more)
        # each factor on each segment: one polynomial piece, the one holding the midpoint, as a
        # polynomial in tau = t - mid: sum_c coef_c tau^c
        taylor = []
        for letter, c, g in moving:
            rate, coeffs = pieces(j, letter)
            xm = (c[seg_line] + g * mid) * rate
            piece = np.floor(xm)
            np.clip(piece, 0, len(coeffs) - 1, out=piece)
            taylor.append(_local_poly(coeffs, piece.astype(np.intp), xm - piece, rate * g))
        seg_integral = _segment_integrals(taylor, half, j)
        res = np.bincount(seg_line, weights=seg_integral, minlength=live.size)
        out[start + live] = total[live] * res
    return out


def line_integral(wavelet, key: str, m: int, spacing_zyx, n, u, v, a, b) -> np.ndarray:
    """Exact footprint ``T_{m,key}(a, b) = ∫ B(X + a u + b v + t n) dt`` at any offsets.

    ``a``, ``b`` (world units, broadcast together) are offsets from the projected support
    centre along u and v.  Between consecutive knot-plane crossings the integrand is one
    polynomial of degree <= 3(j - 1), integrated exactly (closed form for j <= 2,
    Gauss-Legendre otherwise), so the result is exact up to float64 rounding.

    >>> from clwave.model.bspline import SplineWavelet
    >>> from clwave.model.geometry import view_frame
    >>> n, u, v = view_frame(0.0, 0.0)   # look along x: T = ∫phi · phi(b + 1/2) phi(a + 1/2)
    >>> float(line_integral(SplineWavelet(1), "aaa", 0, (1, 1, 1), n, u, v, 0.2, -0.3)[()])
    1.0
    """
    wav = wavelet_for(wavelet)
    key = check_key(key)
    n, u, v = orthonormal_frame(n, u, v)
    a, b = np.broadcast_arrays(np.asarray(a, float), np.asarray(b, float))
    shape = a.shape
    res = exact_samples(wav, key, int(m), spacing_xyz(spacing_zyx), n, u, v,
                              a.reshape(-1).copy(), b.reshape(-1).copy())
    return res.reshape(shape)
