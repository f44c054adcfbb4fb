"""Coarse framebuffers (docs/splatting.md §4): smooth cubic bands drawn at coarser pixels under a
tolerance, then upsampled to the image by the prefiltered cubic B-spline."""

from __future__ import annotations

import dataclasses
from functools import lru_cache

import numpy as np
import scipy.ndimage
import scipy.sparse

from .perspective import axis_scale


#: Coarse framebuffers (docs/splatting.md §4): per band kind, ``(ratio, error)`` points: the worst error, relative to
#: the image maximum, of one band of that kind drawn at coarse pixels of ``ratio * 2^m c`` (level m, c the spacing its
#: footprints vary on) or finer and upsampled, over three views at 256^2 and 512^2 of Shepp-Logan 64^3 and 128^3,
#: hydrogen 128^3, Marschner-Lobb 64^3, a thick-slice Shepp-Logan (16 x 64 x 64 voxels of 2.5 x 0.7 x 0.7) at 5 % kept
#: and random 32^3 and Shepp-Logan 64^3 whole (cubic, 3 levels; every wavelet level's worst).  Below a ratio of
#: about 0.2 the error falls slower than the fourth power, to a floor of 1e-4 to 6e-4 (the texture's bilinear kinks).
COARSE_REFERENCE = dict(
    approximation=((0.05413, 1.4e-4), (0.08800, 1.4e-4), (0.1083, 2.0e-4), (0.1760, 6.1e-4), (0.2165, 1.3e-3),
                   (0.3520, 5.1e-3), (0.4330, 5.8e-3), (0.7040, 6.0e-2)),
    wavelet=((0.05413, 3.0e-4), (0.08800, 6.2e-4), (0.1083, 1.1e-3), (0.1760, 4.4e-3), (0.2165, 6.6e-3),
             (0.3520, 6.2e-2), (0.4330, 9.0e-2), (0.7040, 0.39)))


COARSE_MARGIN = 8  # coarse pixels around the image: the prefilter's mirror ends decay by 0.268^8

#: a volume axis is across the view where the view direction's component along it is below this: no ray slope
#: moves the footprint's variation along that axis (:func:`footprint_scales`, which takes the view's axes'
#: components below it for the round-off of an axis-aligned pose, 0)
ACROSS = 1e-6


def band_factor(ratio: float, level: int, pixel: float, spacing: float) -> int:
    """The largest power of 2 whose coarse pixel, ``factor * pixel``, is at most ``ratio 2^m spacing`` along an image
    axis whose footprints vary on ``spacing`` (:func:`footprint_scales`); the ratios carry 4 digits."""
    factor = 1
    while 2 * factor * pixel <= ratio * 2.0 ** level * spacing * (1 + 1e-3):
        factor *= 2
    return factor


def coarse_plan(order: int, kinds, pixel: float, scales, tolerance: float, square: bool) -> tuple:
    """``(factors, left)``: the framebuffer factors ``(f_u, f_v)`` of each band kind ``(level, approximation)`` in
    ``kinds`` for a tolerance, and what they leave of it.

    The tolerance is spent band kind by band kind, the coarsest wavelet level first (seven bands of the approximation
    band's footprint size), then the approximation band, then the finer wavelet levels: each takes the largest factor
    along each image axis (``pixel`` wide, footprints varying on ``scales``, :func:`footprint_scales`) within the
    largest ratio of :data:`COARSE_REFERENCE` whose error fits what is left, and spends the error tabulated at the
    ratio it draws (the largest over the axes it coarsens), so the errors sum to at most the tolerance.
    ``square``: the lesser factor along both axes (orthographic layers have square pixels).  Only cubic and quintic
    bands are coarsened (the others have kinks; quintic bands, smoother, stay within the cubic budget:
    tests/test_splat.py).

    >>> pixel = 3 ** 0.5 / 2  # 256^3 at 512^2 (the default extent)
    >>> kinds = [(3, True), (3, False), (2, False), (1, False)]
    >>> factors, left = coarse_plan(4, kinds, pixel, (1.0, 1.0), 2e-2, square=True)
    >>> [factors[k][0] for k in kinds], round(left, 6)  # level 3 at 4 (5.8e-3) and 2 (6.6e-3)
    ([4, 2, 1, 1], 0.0076)
    >>> coarse_plan(2, kinds, pixel, (1.0, 1.0), 2e-2, square=True)[0][(3, True)]
    (1, 1)
    """
    factors, left = {}, tolerance
    for level, approximation in sorted(kinds, key=lambda kind: (-kind[0], kind[1])):
        table = COARSE_REFERENCE["approximation" if approximation else "wavelet"]
        ratio = max((r for r, e in table if e <= left), default=0.0) if order >= 4 else 0.0
        fu, fv = (band_factor(ratio, level, pixel, c) for c in scales)
        f = factors[(level, approximation)] = (min(fu, fv),) * 2 if square else (fu, fv)
        if f != (1, 1):  # the ratio drawn along the axes drawn coarse
            drawn = max(fa * pixel / (2.0 ** level * c) for fa, c in zip(f, scales) if fa > 1)
            left -= min(e for r, e in table if r * (1 + 1e-3) >= drawn)
    return factors, max(left, 0.0)


def footprint_scales(view, d_xyz) -> tuple:
    """``(c_u, c_v)``: a spacing that every footprint of ``view`` varies on along u and along v, whatever its ray's
    slope (docs/splatting.md §4 "Thick slices"): :func:`~clwave.splat.perspective.axis_scale` over the volume axes
    across the view (``|n_k|`` below :data:`ACROSS`), whose terms of a sheared axis ``u + s_u n`` no slope changes; at
    least d_min (where :data:`COARSE_REFERENCE` was measured).  A CT's slice axis along v: ``(d_x, d_z)``; a view
    oblique to it: ``(d_min, d_min)``."""
    d = np.asarray(d_xyz, float)
    n, u, v = (np.where(np.abs(x) < ACROSS, 0.0, x) for x in (view.n, view.u, view.v))  # an axis view's round-off
    across = np.where(n == 0.0, d, 0.0)
    return tuple(max(float(d.min()), axis_scale(a, b, across)) for a, b in ((u, v), (v, u)))


def _bspline3(t) -> np.ndarray:
    """The centred cubic B-spline."""
    t = np.abs(t)
    return np.where(t < 1, 2 / 3 - t * t + t ** 3 / 2, np.where(t < 2, (2 - t) ** 3 / 6, 0.0))


class Layer:
    """One framebuffer's view: the image's pixel times ``factors`` ``(f_u, f_v)`` along u and v (coarse bands are
    drawn there; only perspective layers, whose pixels are ray slopes per axis, have ``f_u != f_v``)."""

    def __init__(self, view, factors: tuple):
        H, W = view.size
        fu, fv = factors
        if factors != (1, 1):  # same centre, pixel (perspective: ray slope per pixel) x factor, a margin around it
            size = (-(-H // fv) + 2 * COARSE_MARGIN, -(-W // fu) + 2 * COARSE_MARGIN)
            slope = None if view.slope is None else (view.slope[0] * fu, view.slope[1] * fv)
            view = dataclasses.replace(view, size=size, pixel=view.pixel * fu, slope=slope)
        self.view, self.fine, self.factors = view, (H, W), tuple(factors)

    @property
    def factor(self):
        """What ``meta["framebuffers"]`` lists of this layer: its factor, or ``[f_u, f_v]`` where they differ."""
        fu, fv = self.factors
        return fu if fu == fv else [fu, fv]

    def image(self, pixels: np.ndarray) -> np.ndarray:
        """This framebuffer's (h * w, C) pixels at the image's pixels, (H, W, C) float32."""
        img = pixels.reshape(self.view.size + pixels.shape[1:])
        if self.factors == (1, 1):
            return img
        return np.stack([upsample(img[..., c], self.fine, self.factors) for c in range(img.shape[2])], axis=-1)


def upsample(samples: np.ndarray, shape: tuple, factors) -> np.ndarray:
    """(h, w) samples at coarse pixels -> their prefiltered cubic B-spline interpolant at the
    fine pixel centres of ``shape`` (same centre, ``factors`` ``(f_u, f_v)`` fine pixels per coarse one along
    the columns and along the rows), float32.

    The B-spline coefficients come from ``scipy.ndimage.spline_filter`` (mirrored ends); each
    fine pixel then sums the 4 x 4 coefficients under it, one axis at a time, as sparse products.
    (Dense matrix products did the same through BLAS, whose idle threads then spun on the cores
    the next view's kernels needed.)
    """
    fu, fv = factors
    coeffs = scipy.ndimage.spline_filter(samples, order=3, mode="mirror", output=np.float32)
    rows = _taps(shape[0], samples.shape[0], fv) @ coeffs  # (H, w)
    return rows @ _taps(shape[1], samples.shape[1], fu).T  # (H, W): the sparse factor on the right


@lru_cache(maxsize=16)
def _taps(n: int, coarse: int, factor: int) -> scipy.sparse.csr_matrix:
    """(n, coarse) float32 sparse matrix: the cubic B-spline weights of the 4 coarse coefficients
    under each of n fine pixel centres; fine pixel c lies at coarse index
    ``(c + 1/2 - n/2) / factor + coarse/2 - 1/2`` (taps off the coarse grid are dropped)."""
    at = (np.arange(n) + 0.5 - n / 2) / factor + coarse / 2 - 0.5
    index = np.floor(at).astype(np.intp)[:, None] + np.arange(-1, 3)
    weights = _bspline3(at[:, None] - index) * ((index >= 0) & (index < coarse))
    return scipy.sparse.csr_matrix((weights.astype(np.float32).ravel(), np.clip(index, 0, coarse - 1).ravel(),
                                    np.arange(0, 4 * n + 1, 4)), shape=(n, coarse))
