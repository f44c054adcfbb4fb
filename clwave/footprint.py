"""Footprint textures of the B-spline wavelet prototypes (paper §4, MATH.md §5-6).

The level-m basis function of subband ``key`` whose support box is centred on the world
point X is ::

    B(p) = 2^(-3m/2) prod_a P_a(2^(-m) (p_a - X_a) / d_a + S_a / 2),   a in {x, y, z}

with ``P_a`` = phi = N_j (support [0, j]) or psi (support [0, 2j-1]) by the subband
letter of axis a, ``S_a`` that support length and ``d_a`` the voxel spacing.  Its
footprint is the X-ray of B along the view direction n, in world units::

    T_{m,key}(a, b) = ∫ B(X + a u + b v + t n) dt,        T_m(a, b) = 2^(-m/2) T_0(a/2^m, b/2^m)

so a coefficient c adds ``c T(mu - mu_c, nu - nu_c)`` to the X-ray image.  (n, u, v) is the
orthonormal view frame of paper eq. 31 (CONVENTIONS.md "Camera"); world vectors are
(x, y, z), spacings ``(dz, dy, dx)`` and subband keys are in array-axis order (z, y, x), so
``key[2]`` is the letter of world axis x (MATH.md §4).

Two ways to sample T:

* ``"fft"`` -- projection slicing (paper §4.3): the 2-D spectrum of T is the slice
  ``F(U u + V v)`` of the 3-D spectrum ::

      F(w) = det(D) 2^(3m/2) prod_a G_a(2^m d_a w_a),   G(w) = P^(w) e^(i w S/2)

  Centring each 1-D factor on its support makes it real (phi, and psi of even order:
  symmetric) or purely imaginary (psi of odd order: antisymmetric), and a function of
  ``x`` and ``sin x`` alone: ``G_phi = (sin x / x)^j`` at ``x = w/2`` and
  ``G_psi = 1/2 (sin^2 x / x)^j P(sin^2 x)`` at ``x = w/4``, where the taps q become a
  Chebyshev series in ``sin x`` (``cos(n x) = (-1)^(n/2) T_n(sin x)``,
  ``sin(n x) = (-1)^((n-1)/2) T_n(sin x)``) that psi's j vanishing moments divide by
  ``sin^j x``.  On the grid ``x = alpha k + beta l`` is linear in the frequency indices, so
  ``sin x`` comes from 1-D tables by the addition theorem: no complex exponential and no
  transcendental per grid point.  One real inverse FFT (``irfft2``) of the half-spectrum
  gives the samples of the period-W footprint.  With ``device=`` the half-spectra of
  oblique views are sampled by an OpenCL kernel instead (``cl/footprint.cl``, float32, all
  textures in one launch; :func:`device_spectra`): on 2 CPU cores a view's footprints then
  take half the time (hydrogen at 1 %, 512²: 0.030 -> 0.015 s).
* ``"spatial"`` -- the exact line integral at the same samples: the sorted crossings of
  the line with every moving axis' knot planes (integers of the phi coordinate,
  half-integers of the psi coordinate) cut it into segments where the integrand is one
  polynomial of degree <= 3(j - 1), integrated exactly (closed form for j <= 2,
  Gauss-Legendre otherwise).  Exact up to rounding (:func:`line_integral`).

* ``"cells"`` -- Haar, along each image axis that is a world axis (:func:`cell_axes`).  If
  u = ±e_a, then v_a = n_a = 0 and the footprint factorises as
  ``T(a, b) = P_a(±a / (2^m d_a) + 1/2) T2(b)`` (Haar supports are 1 long): along u it is piecewise constant with its
  jumps on the knots of the projected support (its edges and, for psi, its midpoint), i.e.
  2 cells, whose exact values at the cell centres, looked up by nearest sample, give it
  exactly everywhere.  Sampled at any finer spacing, its jumps fall between samples and
  interpolation misplaces them by up to a texel (at pixels about a voxel wide the pixel
  centres walk slowly across the voxel faces, and the misplaced jumps leave dark stripes).
  The other axis, if it is not a world axis too, is sampled like ``"spatial"`` (T2 has kinks
  there, no jumps).  The texture's path says which axes are cells: ``"cells"`` (both,
  2 x 2 values), ``"cells-u"`` (2 columns, sampled rows) or ``"cells-v"`` (2 rows, sampled
  columns).

``"auto"`` uses FFT for order >= 3 and the spatial path for Haar and linear, whose
footprints have jumps or kinks at axis-aligned views where the band-limited FFT footprint
rings (MATH.md §5).  (The splat renderer's "auto" takes ``"cells"`` for Haar wherever
:func:`cell_axes` allows it.)

Sampling (paper eq. 33-38, MATH.md §5 "per-type rectangular texture"): along u the period
is the tight projected width of the support box, ``W_u = 2^m sum_a |u_a| S_a d_a`` (so the
periodic copies only touch where T = 0), likewise along v, and ::

    N_u = ceil(2^(m+1) omega / dw_u + 1),   dw_u = 2 pi d_min / W_u(m=0),   omega = max(omega_s, omega_min / 2^m)

rounded up to an even ``scipy.fft.next_fast_len``.  The texel spacing is then about
``pi d_min / omega``: omega_s sets one world resolution for all levels (eq. 35/36), and
omega_min keeps the band of every texture, in prototype units, at least omega_min (the
FFT footprint's accuracy, see :data:`DEFAULT_OMEGA_MIN`).  A texture holds the ``N + 1``
samples of the closed box ``[-W_u/2, W_u/2] x [-W_v/2, W_v/2]``.

Examples
--------
>>> from clwave.bspline import SplineWavelet
>>> n, u, v = view_vectors(30.0, 20.0)
>>> tex = footprints(SplineWavelet(4), (1.0, 1.0, 1.0), n, u, v, [(1, "aad")])[(1, "aad")]
>>> tex.path, tex.data.dtype, tex.data.shape == (tex.data.shape[0], 2 * tex.centre_u + 1)
('fft', dtype('float32'), True)
>>> abs(float(tex.data[:-1, :-1].sum()) * tex.h_u * tex.h_v) < 1e-6  # one period: ∫psi = 0
True
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import lru_cache
from math import ceil, comb

import numpy as np
import pyopencl.array as cla
import scipy.fft

from . import programs
from .bspline import SplineWavelet, wavelet_for
from .errors import InputError

#: Default ``omega_min`` per B-spline order: the band, in prototype units, that keeps every
#: FFT footprint within 1e-3 of its level's phi-phi-phi peak at oblique and axis-aligned views
#: (worst case: an axis view, unit spacing, where the slice runs along the slowest-decaying
#: direction of the spectrum).  Measured worst errors / aaa peak, m = 0 and 1, unit and
#: (2, 1, 0.5) spacing: cubic 2.6e-2 at the paper's 14 (MATH.md §5: 3.0e-2), 1.4e-3 at 32,
#: 1.06e-3 at 40, 8.3e-4 at 44, 6.0e-4 at 48; quadratic (C^1, slower) 1.5e-3 at 64, 7.3e-4 at
#: 72, 8.2e-4 at 80 (not monotone), 3.8e-4 at 96.  Oblique views are at float32 rounding
#: (~1e-7) for both.  Orders 1 and 2 take the exact spatial path by default, where the band
#: only sets the texel spacing, so they keep the paper's omega_s alone.
DEFAULT_OMEGA_MIN = {1: 0.0, 2: 0.0, 3: 96.0, 4: 48.0}

_PATHS = ("auto", "fft", "spatial", "cells")


@dataclass
class Texture:
    """One sampled footprint ``T_{level,key}``.

    ``data[iv, iu] = T(a, b)`` at ``a = (iu - centre_u) h_u``, ``b = (iv - centre_v) h_v``
    (world units; rows run along v, columns along u).

    Attributes
    ----------
    data : (Nv, Nu) float32
    h_u, h_v : float
        World spacing of the samples along u and v.
    centre_u, centre_v : float
        Sample coordinates of the support centre (the basis function's projected centre).
    path : str
        ``"fft"``, ``"spatial"``, or ``"cells"``, ``"cells-u"``, ``"cells-v"`` (cells along
        both axes, u only, v only: there the samples are the 2 cell centres of the support,
        for nearest-sample lookup; see :attr:`cells`).
    level : int
    key : str
        Subband key in array-axis order (z, y, x).
    """

    data: np.ndarray
    h_u: float
    h_v: float
    centre_u: float
    centre_v: float
    path: str
    level: int
    key: str

    @property
    def shape(self) -> tuple:
        return self.data.shape

    @property
    def cells(self) -> tuple:
        """``(along u, along v)``: whether the samples of that axis are cells (nearest lookup)."""
        return self.path in ("cells", "cells-u"), self.path in ("cells", "cells-v")

    def coordinates(self) -> tuple:
        """World offsets ``(a, b)`` of the columns and rows from the support centre."""
        nv, nu = self.data.shape
        return (np.arange(nu) - self.centre_u) * self.h_u, (np.arange(nv) - self.centre_v) * self.h_v

    @property
    def box(self) -> tuple:
        """``(a_min, a_max, b_min, b_max)``: the world box the samples cover."""
        a, b = self.coordinates()
        return float(a[0]), float(a[-1]), float(b[0]), float(b[-1])


# ----------------------------------------------------------------------------- sampling
def view_vectors(azimuth: float, elevation: float) -> tuple:
    """The view frame ``(n, u, v)`` of paper eq. 31 for angles in degrees.

    >>> n, u, v = view_vectors(0.0, 0.0)
    >>> n.tolist(), u.tolist(), v.tolist()
    ([1.0, 0.0, 0.0], [-0.0, 1.0, 0.0], [-0.0, -0.0, 1.0])
    """
    a, b = np.radians(azimuth), np.radians(elevation)
    n = np.array([np.cos(a) * np.cos(b), np.sin(a) * np.cos(b), np.sin(b)])
    u = np.array([-np.sin(a), np.cos(a), 0.0])
    v = np.array([-np.cos(a) * np.sin(b), -np.sin(a) * np.sin(b), np.cos(b)])
    return n, u, v


def sample_count(order: int, m: int, omega_s: float = 14.0, width=None) -> int:
    """Paper eq. 33/36: ``N(m) = ceil(2^(m+1) omega_s / dw_0 + 1)``, ``dw_0 = 2 pi / width``.

    ``width`` defaults to the paper's ``sqrt(3) (2j - 1)`` (the diameter of the psi support
    cube).  At omega_s = 14 this reproduces Table I (with j = 1 for Haar; MATH.md §8):

    >>> [sample_count(4, m) for m in range(4)]
    [56, 110, 218, 434]
    """
    if width is None:
        width = np.sqrt(3.0) * (2 * order - 1)
    return int(ceil(2.0 ** (m + 1) * omega_s * width / (2.0 * np.pi) + 1.0))


def _fast_even(n: int) -> int:
    """Smallest even FFT-friendly length >= n."""
    n = scipy.fft.next_fast_len(max(int(n), 2), real=True)
    while n % 2:
        n = scipy.fft.next_fast_len(n + 1, real=True)
    return n


def projected_halfwidths(wavelet, key: str, m: int, spacing_zyx, u, v) -> tuple:
    """Half-widths ``(W_u/2, W_v/2)`` of the tight projected support box, world units.

    ``W_u = 2^m sum_a |u_a| S_a d_a``: the projection of the support box on u.
    """
    wav = wavelet_for(wavelet)
    extent = _extent(wav, _check_key(key), int(m), _spacing_xyz(spacing_zyx))
    return 0.5 * float(np.abs(np.asarray(u, float)) @ extent), 0.5 * float(np.abs(np.asarray(v, float)) @ extent)


# ----------------------------------------------------------------------------- validation
def _spacing_xyz(spacing_zyx) -> np.ndarray:
    s = np.asarray(spacing_zyx, float).reshape(-1)
    if s.shape != (3,) or not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise InputError(f"spacing must be three positive numbers (dz, dy, dx), got {spacing_zyx!r}")
    return s[::-1].copy()


def _check_key(key) -> str:
    if not isinstance(key, str) or len(key) != 3 or set(key) - {"a", "d"}:
        raise InputError(f"subband key must be 3 letters of 'a'/'d' in (z, y, x) order, got {key!r}")
    return key


def _frame(n, u, v) -> tuple:
    """Validate an orthonormal frame; components below 1e-13 (cos 90 deg) are snapped to 0."""
    vecs = []
    for name, vec in (("n", n), ("u", u), ("v", v)):
        a = np.asarray(vec, float).reshape(-1)
        if a.shape != (3,) or not np.all(np.isfinite(a)):
            raise InputError(f"view vector {name} must be 3 finite numbers (x, y, z), got {vec!r}")
        vecs.append(np.where(np.abs(a) < 1e-13, 0.0, a))
    gram = np.array(vecs) @ np.array(vecs).T
    if np.max(np.abs(gram - np.eye(3))) > 1e-6:
        raise InputError("n, u, v must be orthonormal (paper eq. 31; see footprint.view_vectors)")
    return tuple(vecs)


def _extent(wav: SplineWavelet, key: str, m: int, d_xyz) -> np.ndarray:
    """World edge lengths of the support box, (x, y, z): ``2^m S_a d_a``."""
    key_xyz = key[::-1]
    return np.array([2.0 ** m * wav.support(key_xyz[a]) * d_xyz[a] for a in range(3)])


def cell_axes(wavelet, u, v) -> tuple:
    """``(along u, along v)``: where the ``"cells"`` lookup is exact, i.e. Haar and the image
    axis along a world axis (the footprint is piecewise constant along it, 2 cells).

    >>> n, u, v = view_vectors(90.0, 0.0)
    >>> cell_axes("haar", u, v), cell_axes("linear", u, v), cell_axes("haar", *view_vectors(0.0, 10.0)[1:])
    ((True, True), (False, False), (True, False))
    """
    haar = wavelet_for(wavelet).order == 1
    return tuple(bool(haar and np.max(np.abs(np.asarray(w, float))) > 1.0 - 1e-12) for w in (u, v))


def _vanishes(key: str, n) -> bool:
    """psi along an axis parallel to n integrates to 0 along every line: T == 0."""
    key_xyz = key[::-1]
    return any(key_xyz[a] == "d" and abs(n[a]) > 1.0 - 1e-12 for a in range(3))


# ----------------------------------------------------------------------------- Fourier factors
@lru_cache(maxsize=None)
def _psi_poly(order: int) -> tuple:
    """The tap sum of psi's centred transform as a polynomial: ``(coeffs, imaginary)``.

    ``sum_k q_k e^(-i n_k t) = (-i)^imaginary s^j P(s^2)`` with ``s = sin t``,
    ``n_k = 2k - (3j - 2)`` and ``P = sum_r coeffs[r] (s^2)^r``.  The factor ``s^j`` is psi's
    j vanishing moments (``Q`` has the root ``(1 - e^(-iw))^j``).
    """
    q = SplineWavelet(order).q
    K = len(q) - 1
    if np.allclose(q, q[::-1], rtol=0, atol=1e-15):
        imaginary = False
    elif np.allclose(q, -q[::-1], rtol=0, atol=1e-15):
        imaginary = True
    else:  # pragma: no cover - every CDF(j, j) bank is (anti)symmetric
        raise InputError("footprints need (anti)symmetric wavelet taps")
    cheb = np.zeros(K + 1)
    for k, qk in enumerate(q):
        nk = 2 * k - K
        r = abs(nk)
        if imaginary:  # -i sum q_k sin(n_k t), sin(r t) = (-1)^((r-1)/2) T_r(sin t) for odd r
            cheb[r] += qk * np.sign(nk) * (-1) ** ((r - 1) // 2)
        else:  # cos(r t) = (-1)^(r/2) T_r(sin t) for even r
            cheb[r] += qk * (-1) ** (r // 2)
    power = np.polynomial.chebyshev.cheb2poly(cheb)
    j = order
    low, rest = power[:j], power[j:]
    if np.max(np.abs(low)) > 1e-12 or np.max(np.abs(rest[1::2]), initial=0.0) > 1e-12:
        raise InputError("footprints need psi with j vanishing moments")  # pragma: no cover
    return tuple(rest[0::2]), imaginary


def _poly(coeffs, z):
    """``sum_r coeffs[r] z^r`` by Horner, in place on one new array."""
    if len(coeffs) == 1:
        return coeffs[0]
    out = z * coeffs[-1]
    out += coeffs[-2]
    for c in coeffs[-3::-1]:
        out *= z
        out += c
    return out


def _small_positions(x, a_, b_, ku, kv):
    """Indices where ``|x| = |a_ ku + b_ kv| < 1e-4`` on a (kv, ku) block (sin(x)/x needs care there)."""
    if x.shape[0] > 1 and x.shape[1] > 1 and abs(a_) >= 1e-3:
        # at most two ku per row kv lie that close to the root ku* = -b_ kv / a_
        kc = np.floor(-b_ * kv / a_)[:, None] + np.array([0.0, 1.0])
        ok = (kc >= 0) & (kc < len(ku))
        kc = np.clip(kc, 0, len(ku) - 1).astype(np.intp)
        rows = np.broadcast_to(np.arange(len(kv))[:, None], kc.shape)
        ok &= np.abs(x[rows, kc]) < 1e-4
        return rows[ok], kc[ok]
    return np.nonzero(np.abs(x) < 1e-4)


_RATE = dict(a=2.0, d=4.0)  # x = w / rate: phi's factors are functions of w/2, psi's of w/4
_WEIGHT = dict(a=1.0, d=0.5)  # the constant in front of each centred factor G


class _Axis:
    """One axis of the slice ``G(2^m d_a (U u_a + V v_a))`` at ``U = ku du``, ``V = kv dv``.

    With ``x = a_ ku + b_ kv`` (x = w/2 for phi, w/4 for psi; ``alpha``, ``beta`` are w per
    unit ku and kv) ::

        G = weight (-i)^imaginary (num / x)^j poly,
        phi: num = sin x, poly = 1;   psi: num = sin^2 x, poly = P(sin^2 x)  (:func:`_psi_poly`)

    Sines come from the 1-D tables by the addition theorem: no transcendental per grid point.
    """

    def __init__(self, order, letter, alpha, beta, ku, kv):
        self.order, self.letter = order, letter
        self.a_, self.b_ = alpha / _RATE[letter], beta / _RATE[letter]
        self.kind = "row" if self.b_ == 0.0 else "col" if self.a_ == 0.0 else "full"
        self.ku, self.kv = ku, kv
        self.ak, self.bl = self.a_ * ku, self.b_ * kv
        self.sa, self.ca = np.sin(self.ak), np.cos(self.ak)
        self.sb, self.cb = np.sin(self.bl), np.cos(self.bl)
        self.weight = _WEIGHT[letter]
        self.coeffs, self.imaginary = _psi_poly(order) if letter == "d" else (None, False)

    def block(self, r0, r1):
        """``(num, x, poly)`` on rows r0:r1 (arrays of their own; 1-D kinds stay 1-D)."""
        if self.kind == "row":
            x, s = self.ak[None, :].copy(), self.sa[None, :].copy()
        elif self.kind == "col":
            x, s = self.bl[r0:r1, None].copy(), self.sb[r0:r1, None].copy()
        else:
            x = np.add.outer(self.bl[r0:r1], self.ak)
            s = np.multiply.outer(self.sb[r0:r1], self.ca)
            s += np.multiply.outer(self.cb[r0:r1], self.sa)
        if self.letter == "a":
            num, poly = s, None
        else:
            num = s * s
            poly = _poly(self.coeffs, num)
        small = _small_positions(x, self.a_, self.b_, self.ku, self.kv[r0:r1])
        if len(small[0]):
            xs = x[small]
            sinc = 1.0 - xs * xs / 6.0  # sin(x)/x to 1e-17 for |x| < 1e-4
            num[small] = sinc if self.letter == "a" else sinc * s[small]
            x[small] = 1.0
        return num, x, poly

    def values(self):
        """The complex factor G on the whole (kv, ku) grid, broadcastable."""
        num, x, poly = self.block(0, len(self.kv))
        g = self.weight * _ipow(num / x, self.order)
        if poly is not None:
            g = g * poly
        return g * (-1j) ** self.imaginary


def centred_fourier(wavelet, letter: str, w) -> np.ndarray:
    """``G(w) = ∫ P(x + S/2) e^(-i w x) dx``, the transform of the prototype centred on its support.

    Real for phi and even-order psi, purely imaginary for odd-order psi.

    >>> from clwave.bspline import SplineWavelet
    >>> float(centred_fourier(SplineWavelet(4), "a", 0.0).real)
    1.0
    """
    wav = wavelet_for(wavelet)
    w = np.asarray(w, float)
    g = _Axis(wav.order, letter, 1.0, 0.0, w.reshape(-1), np.zeros(1)).values()
    return np.broadcast_to(g, (1, w.size)).reshape(w.shape)


def _ipow(x, j: int):
    """``x**j`` for a positive integer j by squaring, reusing x (numpy's float pow is slow)."""
    out = None
    while True:
        if j & 1:
            if out is None:
                out = x.copy() if j > 1 else x
            else:
                out *= x
        j >>= 1
        if not j:
            return out
        x *= x


def _slice_plan(wav, key, m, d_xyz, u, v, wu, wv) -> tuple:
    """``(scale, axes)`` of the slice ``F(U u + V v)`` of a period-(W_u, W_v) texture at
    ``U = ku 2 pi / W_u``, ``V = kv 2 pi / W_v``.

    ``axes`` holds ``(letter, alpha, beta)`` of each world axis not parallel to n (alpha and
    beta: w per unit ku and kv); ``scale`` is the real constant of the product of their
    centred factors, with psi's weights 1/2 (0 where psi lies along n).  The spectrum is
    ``scale (-i)^imaginary prod G`` (:class:`_Axis`), times N_u N_v for an inverse FFT.
    """
    du, dv = 2.0 * np.pi / wu, 2.0 * np.pi / wv
    # det(D) 2^(3m/2) from F; 1/(W_u W_v) from the Fourier series of the periodised T
    scale = float(np.prod(d_xyz)) * 2.0 ** (1.5 * m) / (wu * wv)
    axes, key_xyz = [], key[::-1]
    for a in range(3):
        dilation = 2.0 ** m * d_xyz[a]
        alpha, beta = dilation * du * u[a], dilation * dv * v[a]
        if alpha == 0.0 and beta == 0.0:  # axis parallel to n: the factor is G(0), 1 for phi
            scale *= 1.0 if key_xyz[a] == "a" else 0.0
            continue
        axes.append((key_xyz[a], alpha, beta))
    return scale * float(np.prod([_WEIGHT[letter] for letter, _, _ in axes])), axes


def _fft_texture(wav, key, m, d_xyz, u, v, nu, nv, wu, wv, workers=-1, block=16384) -> np.ndarray:
    """Period-(W_u, W_v) samples of T at ``a = p h_u``, ``b = q h_v`` in FFT order, (nv, nu)."""
    ku = np.arange(nu // 2 + 1, dtype=float)         # U = ku du, the rfft half
    kv = np.fft.fftfreq(nv, 1.0 / nv)                # V = kv dv, FFT order
    scale, plan = _slice_plan(wav, key, m, d_xyz, u, v, wu, wv)
    const = scale * nu * nv  # N_u N_v undoes the inverse transform's 1/N
    axes = [_Axis(wav.order, letter, alpha, beta, ku, kv) for letter, alpha, beta in plan]
    phase = (-1j) ** sum(ax.imaginary for ax in axes) * const
    if all(ax.kind != "full" for ax in axes):
        # separable (axis-aligned views): T = t_v(b) t_u(a), each 1-D spectrum Hermitian
        def spectrum(kind):
            g = 1.0
            for ax in axes:
                if ax.kind == kind:
                    num, x, poly = ax.block(0, len(kv))
                    g = g * _ipow(num / x, wav.order) * (1.0 if poly is None else poly)
                    g = g * (-1j) ** ax.imaginary
            return np.reshape(g, -1)
        tu = scipy.fft.irfft(spectrum("row"), n=nu)
        tv = scipy.fft.ifft(spectrum("col")).real
        return np.multiply.outer(tv * const, tu)
    # general view: the spectrum in blocks of rows that stay in cache
    axes.sort(key=lambda ax: ("full", "col", "row").index(ax.kind))  # the first product is 2-D
    spec = np.empty((nv, len(ku)), complex)
    rows = max(1, block // len(ku))
    for r0 in range(0, nv, rows):
        r1 = min(nv, r0 + rows)
        parts = [ax.block(r0, r1) for ax in axes]
        ratio = parts[0][0] * parts[1][0]
        den = parts[0][1] * parts[1][1]
        for num, x, _ in parts[2:]:
            ratio *= num
            den *= x
        ratio /= den
        ratio = _ipow(ratio, wav.order)
        for _, _, poly in parts:
            if poly is not None:
                ratio *= poly
        np.multiply(ratio, phase, out=spec[r0:r1])
    return scipy.fft.irfft2(spec, s=(nv, nu), workers=workers, overwrite_x=True)


SPECTRUM_GROUP = 16  # work-items per work-group of cl/footprint.cl, each group within one texture
SPECTRUM_BLOCK = 16  # columns per work-item: the kernel's float16


def device_spectra(cc, order: int, plans) -> list:
    """Half-spectra of textures on an OpenCL device (``cl/footprint.cl``), in one launch.

    ``plans`` holds ``(scale, axes, nu, nv)`` per texture (:func:`_slice_plan`); each spectrum
    comes back as an ``(nv, nu // 2 + 1)`` complex64 view in FFT row order, scaled for
    ``irfft2`` (float32 throughout: the textures are within ~1e-6 of their peak from those of
    the float64 NumPy spectra).
    """
    if not plans:
        return []
    coeffs, imaginary = _psi_poly(order)
    sizes, rates, group_tex, first = [], [], [], 0
    for t, (scale, axes, nu, nv) in enumerate(plans):
        rate, psi = np.zeros(8), 0  # absent axes: phi at rate 0, a factor of 1
        for a, (letter, alpha, beta) in enumerate(axes):
            rate[2 * a: 2 * a + 2] = alpha / _RATE[letter], beta / _RATE[letter]
            psi |= (letter == "d") << a
        phase = scale * nu * nv * (-1j) ** (imaginary * bin(psi).count("1"))
        rate[6:] = phase.real, phase.imag
        blocks = -(-(nu // 2 + 1) // SPECTRUM_BLOCK)
        sizes.append((first, nv, blocks, psi))
        rates.append(rate)
        groups = -(-nv * blocks // SPECTRUM_GROUP)
        group_tex += [t] * groups
        first += groups * SPECTRUM_GROUP
    q = cc.queue
    out = cla.empty(q, (first * SPECTRUM_BLOCK,), np.complex64)
    kernels = programs.build(cc, ["footprint.cl"], {"CLW_ORDER": order, "CLW_TERMS": len(coeffs)})
    kernels.footprint_spectra(q, (first,), (SPECTRUM_GROUP,), cc.upload(np.array(group_tex, np.int32)),
                              cc.upload(np.array(sizes, np.int32)), cc.upload(np.array(rates, np.float32)),
                              cc.upload(np.array(coeffs, np.float32)), out.data)
    spectra = out.get()
    return [spectra[f * SPECTRUM_BLOCK: (f + nv * blocks) * SPECTRUM_BLOCK].reshape(nv, -1)[:, : nu // 2 + 1]
            for (f, nv, blocks, _), (_, _, nu, _) in zip(sizes, plans)]


# ----------------------------------------------------------------------------- exact line integral
@lru_cache(maxsize=None)
def _pieces(order: int, letter: str) -> tuple:
    """Piecewise-polynomial table of a prototype: ``(rate, coeffs)``.

    Piece i covers ``[i/rate, (i+1)/rate)`` and there ``P(x) = sum_c coeffs[i, c] y^c`` with
    ``y = rate x - i`` in [0, 1).  Fitted from exact samples (interpolation of degree j-1,
    exact up to rounding).
    """
    wav = SplineWavelet(order)
    rate = 1 if letter == "a" else 2
    count = wav.support(letter) * rate
    deg = order - 1
    y = 0.5 - 0.5 * np.cos(np.pi * (np.arange(deg + 1) + 0.5) / (deg + 1))  # Chebyshev nodes in (0, 1)
    coeffs = np.empty((count, deg + 1))
    for i in range(count):
        vals = wav.prototype(letter, (i + y) / rate)
        coeffs[i] = np.linalg.solve(np.vander(y, deg + 1, increasing=True), vals)
    return rate, coeffs


def _eval_pieces(order, letter, x) -> np.ndarray:
    """Evaluate a prototype from its table (0 outside its half-open support)."""
    rate, coeffs = _pieces(order, letter)
    xs = np.asarray(x, float) * rate
    piece = np.floor(xs)
    inside = (piece >= 0) & (piece < len(coeffs))
    idx = np.clip(piece, 0, len(coeffs) - 1).astype(np.intp)
    y = xs - idx
    out = coeffs[idx, -1]
    for c in range(coeffs.shape[1] - 2, -1, -1):
        out = out * y + coeffs[idx, c]
    return np.where(inside, out, 0.0)


def _gauss_points(order: int) -> int:
    """Gauss-Legendre nodes exact for the product of three degree-(j-1) pieces."""
    return max(1, ceil((3 * (order - 1) + 1) / 2))


@lru_cache(maxsize=None)
def _knots(order: int, letter: str) -> np.ndarray:
    """Knots of a prototype: integers 0..j for phi, half-integers 0..2j-1 for psi."""
    rate = 1 if letter == "a" else 2
    return np.arange(SplineWavelet(order).support(letter) * rate + 1) / rate


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


def _line_integral_flat(wav, key, m, d_xyz, n, u, v, a, b, chunk=4096) -> np.ndarray:
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
                total *= _eval_pieces(j, letter, c)
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
        t = np.concatenate([np.subtract.outer(c / -g, _knots(j, letter) / -g) for letter, c, g in moving], axis=1)
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
            rate, coeffs = _pieces(j, letter)
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

    >>> from clwave.bspline import SplineWavelet
    >>> n, u, v = view_vectors(0.0, 0.0)   # look along x: T = ∫phi · phi(b + 1/2) phi(a + 1/2)
    >>> float(line_integral(SplineWavelet(1), "aaa", 0, (1, 1, 1), n, u, v, 0.2, -0.3)[()])
    1.0
    """
    wav = wavelet_for(wavelet)
    key = _check_key(key)
    n, u, v = _frame(n, u, v)
    a, b = np.broadcast_arrays(np.asarray(a, float), np.asarray(b, float))
    shape = a.shape
    res = _line_integral_flat(wav, key, int(m), _spacing_xyz(spacing_zyx), n, u, v,
                              a.reshape(-1).copy(), b.reshape(-1).copy())
    return res.reshape(shape)


# ----------------------------------------------------------------------------- textures
def _centred(t, dtype) -> np.ndarray:
    """FFT-order samples (sample 0 at a = b = 0) to the closed box, centre at ``(N//2, N//2)``.

    Row and column N repeat row and column 0 (the period is the box width), so the box
    ``[-W/2, W/2]`` is closed on both sides.
    """
    nv, nu = t.shape
    hv, hu = nv // 2, nu // 2  # N even: N - N//2 == N//2
    out = np.empty((nv + 1, nu + 1), dtype)
    out[hv:nv, hu:nu] = t[:hv, :hu]
    out[hv:nv, :hu] = t[:hv, hu:]
    out[:hv, hu:nu] = t[hv:, :hu]
    out[:hv, :hu] = t[hv:, hu:]
    out[:nv, nu] = out[:nv, 0]
    out[nv] = out[0]
    return out


def _trim(data, centre_u, centre_v, tol):
    if tol <= 0:
        return data, centre_u, centre_v
    mask = np.abs(data) > tol * np.max(np.abs(data))
    if not mask.any():
        return data[:1, :1], 0.0, 0.0
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    return data[r0:r1, c0:c1], centre_u - c0, centre_v - r0


def _cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        return os.cpu_count() or 1


@lru_cache(maxsize=1)
def _pool() -> ThreadPoolExecutor:
    """One thread per core for texture making, kept for the process (starting threads for every
    view and level cost more than a small view's FFTs)."""
    return ThreadPoolExecutor(_cpu_count(), thread_name_prefix="clwave-footprints")


if hasattr(os, "register_at_fork"):  # a forked child has none of the parent's threads: a pool of its own
    os.register_at_fork(after_in_child=_pool.cache_clear)


def _axis_sampling(width, cell, omega, d_min, texel) -> tuple:
    """``(N, h, cell)`` of one texture axis whose support is ``width`` wide (world units).

    Cells: the 2 halves of the support, ``h = width / 2``.  Otherwise eq. 36 with the
    per-type period, ``N = 2^(m+1) omega / dw``, ``dw = 2 pi d_min / W(m=0)``, ``h = width / N``;
    or, with ``texel``, ``h = texel`` and the period ``N h`` a little beyond the support.
    """
    if cell:
        return 2, width / 2.0, True
    if texel is None:
        count = _fast_even(ceil(2.0 * omega * width / (2.0 * np.pi * d_min) + 1.0))
        return count, width / count, False
    return _fast_even(ceil(width / texel)), float(texel), False


def _axis_points(count, h, cell) -> tuple:
    """Sample offsets from the support centre along one axis, and the centre's sample coordinate:
    the 2 cell centres (a quarter of the support out), or the ``count + 1`` samples of the
    closed box ``[-count h / 2, count h / 2]``."""
    centre = 0.5 if cell else float(count // 2)
    return (np.arange(2 if cell else count + 1) - centre) * h, centre


def footprints(wavelet, spacing_zyx, n, u, v, bands, omega_s: float = 14.0, omega_min=None,
               path: str = "auto", tol: float = 0.0, texel=None, device=None) -> dict:
    """Footprint textures of the (level, key) pairs in ``bands`` for one view.

    Parameters
    ----------
    wavelet : SplineWavelet, name or order
    spacing_zyx : (dz, dy, dx)
        Voxel spacing in world units.
    n, u, v : (3,) arrays, world (x, y, z)
        Orthonormal view frame (paper eq. 31): n towards the camera, u right, v up.
    bands : iterable of (m, key)
        Levels (0 = the voxels' own B-splines) and 3-letter subband keys in (z, y, x) order.
    omega_s : float
        Band of eq. 35/36: texel spacing about ``pi d_min / omega_s`` at every level.
    omega_min : float, optional
        Least band of any texture in prototype units; default :data:`DEFAULT_OMEGA_MIN`.
    path : "auto", "fft", "spatial" or "cells"
        "auto": FFT for order >= 3, exact spatial sampling for Haar and linear; "cells"
        (Haar with u or v along a world axis, :func:`cell_axes`): along each such axis
        the exact values of the 2 cells between the knots, for nearest-sample lookup, and
        spatial samples along the other; the textures' path is then "cells", "cells-u"
        or "cells-v" (which axes are cells).
    tol : float
        Trim each texture to the bounding box of samples above ``tol`` times its peak
        magnitude (0: keep the tight projected support box).
    texel : float or dict, optional
        Sample spacing in world units, for every texture or per band (``{(m, key): texel}``),
        overriding the counts of eq. 36 (the splat renderer asks for an exact fraction of
        its pixel); the FFT period is then the smallest multiple of it that covers the
        support.  Not used along cell axes.
    device : ComputeContext, optional
        Sample the FFT path's spectra there (:func:`device_spectra`, float32), all
        textures in one launch, instead of with NumPy (float64); the inverse FFTs stay on
        the host.

    Returns
    -------
    dict mapping (m, key) to :class:`Texture`, or to None where the footprint vanishes
    identically (psi along an axis parallel to n).
    """
    wav = wavelet_for(wavelet)
    d_xyz = _spacing_xyz(spacing_zyx)
    n, u, v = _frame(n, u, v)
    if path not in _PATHS:
        raise InputError(f"footprint path must be one of {', '.join(_PATHS)}, got {path!r}")
    if not (np.isfinite(omega_s) and omega_s > 0):
        raise InputError(f"omega_s must be a positive number, got {omega_s!r}")
    if omega_min is None:
        omega_min = DEFAULT_OMEGA_MIN.get(wav.order, 64.0)
    if not (np.isfinite(omega_min) and omega_min >= 0):
        raise InputError(f"omega_min must be a number >= 0, got {omega_min!r}")
    for h in (texel.values() if isinstance(texel, dict) else [texel]):
        if h is not None and not (np.isfinite(h) and h > 0):
            raise InputError(f"texel must be a positive world length, got {h!r}")
    if path == "auto":
        path = "fft" if wav.order >= 3 else "spatial"
    cells = cell_axes(wav, u, v) if path == "cells" else (False, False)
    if path == "cells" and not any(cells):
        raise InputError("footprint path 'cells' needs Haar at a view with u or v along a world axis")
    name = {(True, True): "cells", (True, False): "cells-u", (False, True): "cells-v"}.get(cells, path)
    d_min = float(d_xyz.min())
    out, jobs = {}, []
    for band in bands:
        m, key = band
        m, key = int(m), _check_key(key)
        if m < 0:
            raise InputError(f"footprint level must be >= 0, got {m}")
        if _vanishes(key, n):
            out[(m, key)] = None
            continue
        extent = _extent(wav, key, m, d_xyz)
        omega = max(float(omega_s), float(omega_min) / 2.0 ** m)
        out[(m, key)] = None
        h = texel.get((m, key)) if isinstance(texel, dict) else texel
        jobs.append((m, key) + tuple(_axis_sampling(float(np.abs(w) @ extent), cell, omega, d_min, h)
                                     for w, cell in ((u, cells[0]), (v, cells[1]))))
    spectra = {}
    if path == "fft" and device is not None:
        # 2-D spectra on the device; at axis-aligned views (every axis along u or v) the texture
        # is separable and its two 1-D transforms on the host are cheaper
        plans = {}
        for m, key, (nu, h_u, _), (nv, h_v, _) in jobs:
            scale, axes = _slice_plan(wav, key, m, d_xyz, u, v, nu * h_u, nv * h_v)
            if any(alpha and beta for _, alpha, beta in axes):
                plans[(m, key)] = (scale, axes, nu, nv)
        spectra = dict(zip(plans, device_spectra(device, wav.order, list(plans.values()))))

    def make(job):
        m, key, (nu, h_u, cell_u), (nv, h_v, cell_v) = job
        if path == "fft":
            if (m, key) in spectra:
                period = scipy.fft.irfft2(spectra[(m, key)], s=(nv, nu), workers=workers, overwrite_x=True)
            else:
                period = _fft_texture(wav, key, m, d_xyz, u, v, nu, nv, nu * h_u, nv * h_v, workers)
            data = _centred(period, np.float32)
            cu, cv = float(nu // 2), float(nv // 2)
        else:
            (aa, cu), (bb, cv) = _axis_points(nu, h_u, cell_u), _axis_points(nv, h_v, cell_v)
            shape = (len(bb), len(aa))
            data = _line_integral_flat(wav, key, m, d_xyz, n, u, v,
                                       np.broadcast_to(aa, shape).reshape(-1),
                                       np.broadcast_to(bb[:, None], shape).reshape(-1))
            data = data.reshape(shape).astype(np.float32)
        data, cu, cv = _trim(data, cu, cv, float(tol))
        return Texture(np.ascontiguousarray(data), h_u, h_v, cu, cv, name, m, key)

    # numpy and pocketfft release the GIL: textures in parallel, largest first, where the
    # work outweighs the threads' overhead (measured on 2 cores: a gain from ~1e5 texels)
    if len(jobs) > 1 and _cpu_count() > 1 and sum(job[2][0] * job[3][0] for job in jobs) >= 1 << 17:
        workers = 1
        jobs.sort(key=lambda job: -job[2][0] * job[3][0])
        textures = list(_pool().map(make, jobs))
    else:
        workers = -1
        textures = [make(job) for job in jobs]
    for tex in textures:
        out[(tex.level, tex.key)] = tex
    return out
