"""Cardinal B-splines and the spline wavelets of docs/model.md §1-4 and docs/splatting.md §1: CDF(j, j) for
orders 1-4 and CDF(6, 6) lifted to a better condition number for order 6 (docs/model.md §2).

Everything the renderers need about one basis order lives here: the
closed-form scaling function ``N_j`` and wavelet ``psi = sum_k q_k N_j(2x - k)``
with their derivatives and Fourier transforms, the PyWavelets filter bank, the
per-level index offsets of ``mode='zero'`` (docs/model.md §4), and the L2 norms used
for thresholding (docs/model.md §2).  Coordinates are fine-voxel units: voxel
``i`` carries ``N_j(x - i)`` with support ``[i, i + j]``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache
from math import comb, factorial

import numpy as np
import pywt

from ..errors import InputError

_R2 = 1.0 / np.sqrt(2.0)

# PyWavelets filter banks (each array times 1/sqrt(2)) and their alignment
# constants (F, A, B) from docs/model.md §2; synthesis p, q are the non-zero taps
# of rec_lo and rec_hi.
_BANKS = {
    1: dict(A=1, B=1, dec_lo=[1, 1], dec_hi=[-1, 1], rec_lo=[1, 1], rec_hi=[1, -1]),
    2: dict(A=4, B=4,
            dec_lo=np.array([0, -1, 2, 6, 2, -1]) / 4, dec_hi=np.array([0, -1, 2, -1, 0, 0]) / 2,
            rec_lo=np.array([0, 1, 2, 1, 0, 0]) / 2, rec_hi=np.array([0, -1, -2, 6, -2, -1]) / 4),
    3: dict(A=5, B=7,
            dec_lo=np.array([3, -9, -7, 45, 45, -7, -9, 3]) / 32,
            dec_hi=np.array([0, 0, -1, 3, -3, 1, 0, 0]) / 4,
            rec_lo=np.array([0, 0, 1, 3, 3, 1, 0, 0]) / 4,
            rec_hi=np.array([3, 9, -7, -45, 45, 7, -9, -3]) / 32),
    4: dict(A=8, B=10,
            dec_lo=np.array([0, -5, 20, -1, -96, 70, 280, 70, -96, -1, 20, -5]) / 128,
            dec_hi=np.array([0, 0, 0, -1, 4, -6, 4, -1, 0, 0, 0, 0]) / 8,
            rec_lo=np.array([0, 0, 0, 1, 4, 6, 4, 1, 0, 0, 0, 0]) / 8,
            rec_hi=np.array([0, -5, -20, -1, 96, 70, -280, 70, 96, -1, -20, -5]) / 128),
    # CDF(6, 6) with psi lifted by -sum_n s_n N_6(x - n), s = (1377, -3282, 1905, 1905, -3282, 1377) / 4096:
    # condition number 123 -> 43, support [0, 11] kept (docs/model.md §2, tools/order6_banks.py)
    6: dict(A=12, B=16,
            dec_lo=np.array([0, -2385, 14310, -24989, -17016, 97134, -28124, -204387, 96366, 400326, 96366,
                             -204387, -28124, 97134, -17016, -24989, 14310, -2385]) / 131072,
            dec_hi=np.array([0, 0, 0, 0, 0, -1, 6, -15, 20, -15, 6, -1, 0, 0, 0, 0, 0, 0]) / 32,
            rec_lo=np.array([0, 0, 0, 0, 0, 1, 6, 15, 20, 15, 6, 1, 0, 0, 0, 0, 0, 0]) / 32,
            rec_hi=np.array([0, -2385, -14310, -24989, 17016, 97134, 28124, -204387, -96366, 400326, -96366,
                             -204387, 28124, 97134, 17016, -24989, -14310, -2385]) / 131072),
}

WAVELET_ORDERS = {"haar": 1, "linear": 2, "quadratic": 3, "cubic": 4, "quintic": 6}


def bspline(j: int, x) -> np.ndarray:
    """Cardinal B-spline ``N_j(x)`` of order j (degree j-1, support [0, j]).

    Cox-de Boor recursion ``N_j(x) = [x N_{j-1}(x) + (j - x) N_{j-1}(x - 1)] / (j - 1)``
    with ``N_1`` the indicator of [0, 1).

    >>> float(bspline(4, 2.0))  # cubic peak
    0.6666666666666666
    """
    x = np.asarray(x, dtype=float)
    if j < 1:
        return np.zeros_like(x)
    # values N_1(x - i) for the j unit cells, then raise the order in place
    cells = [((x >= i) & (x < i + 1)).astype(float) for i in range(j)]
    for order in range(2, j + 1):
        cells = [((x - i) * cells[i] + (i + order - x) * cells[i + 1]) / (order - 1)
                 for i in range(j - order + 1)]
    return cells[0]


def bspline_derivative(j: int, x, d: int = 1) -> np.ndarray:
    """d-th derivative of ``N_j``: ``sum_i (-1)^i C(d, i) N_{j-d}(x - i)`` (docs/model.md §1)."""
    x = np.asarray(x, dtype=float)
    return sum((-1) ** i * comb(d, i) * bspline(j - d, x - i) for i in range(d + 1))


def bspline_explicit(j: int, x) -> np.ndarray:
    """The explicit truncated-power form of ``N_j`` (an independent check of :func:`bspline`)."""
    x = np.asarray(x, dtype=float)
    # (x - k)_+^(j-1), with the order-1 power read as the right-continuous step
    total = sum((-1) ** k * comb(j, k) * np.where(x >= k, np.abs(x - k) ** (j - 1), 0.0)
                for k in range(j + 1))
    inside = (x >= 0) & (x < j)
    return np.where(inside, total / factorial(j - 1), 0.0)


@dataclass(frozen=True)
class SplineWavelet:
    """The B-spline wavelet of order ``j`` (1 = Haar ... 4 = cubic, 6 = quintic; docs/model.md §1-2)."""

    order: int

    def __post_init__(self):
        if self.order not in _BANKS:
            raise InputError(f"unsupported B-spline order {self.order}; use one of {', '.join(map(str, _BANKS))}")

    # --- names and filters -------------------------------------------------
    @property
    def name(self) -> str:
        return {v: k for k, v in WAVELET_ORDERS.items()}[self.order]

    @cached_property
    def bank(self) -> dict:
        return {k: v if k in ("A", "B") else np.asarray(v, float) * _R2
                for k, v in _BANKS[self.order].items()}

    @cached_property
    def pywt(self) -> pywt.Wavelet:
        b = self.bank
        return pywt.Wavelet(f"clwave-{self.name}",
                            filter_bank=[b["dec_lo"], b["dec_hi"], b["rec_lo"], b["rec_hi"]])

    @cached_property
    def p(self) -> np.ndarray:
        """Two-scale coefficients ``phi(x) = sum_k p_k phi(2x - k)``, k = 0..j."""
        return np.trim_zeros(self.bank["rec_lo"]) * np.sqrt(2.0)

    @cached_property
    def q(self) -> np.ndarray:
        """Wavelet coefficients ``psi(x) = sum_k q_k N_j(2x - k)``, k = 0..3j-2."""
        return np.trim_zeros(self.bank["rec_hi"]) * np.sqrt(2.0)

    # --- supports and offsets (docs/model.md §4) ----------------------------------
    def support(self, letter: str) -> int:
        """Support length of the prototype: j for 'a' (phi), 2j-1 for 'd' (psi)."""
        return self.order if letter == "a" else 2 * self.order - 1

    def offset(self, letter: str, m: int) -> int:
        """Fine-voxel offset o_m of level-m bands: ``oA_m`` for 'a', ``oD_m`` for 'd'."""
        A, B = self.bank["A"], self.bank["B"]
        if letter == "a" or m == 0:
            return (2 ** m - 1) * (1 - A)
        return (2 ** (m - 1) - 1) * (1 - A) + 2 ** (m - 1) * (1 - B)

    def synthesis_shift(self, letter: str) -> int:
        """Index shift of one synthesis step: child l = 2k + i + shift (from the offsets)."""
        return 1 - (self.bank["A"] if letter == "a" else self.bank["B"])

    # --- closed-form prototypes --------------------------------------------
    def phi(self, x, d: int = 0) -> np.ndarray:
        """``N_j`` (d = 0) or its first derivative (d = 1)."""
        return bspline(self.order, x) if d == 0 else bspline_derivative(self.order, x, d)

    def psi(self, x, d: int = 0) -> np.ndarray:
        """``psi(x) = sum_k q_k N_j(2x - k)``; its derivative carries the chain factor 2."""
        x = np.asarray(x, float)
        return (2.0 ** d) * sum(qk * self.phi(2 * x - k, d) for k, qk in enumerate(self.q))

    def prototype(self, letter: str, x, d: int = 0) -> np.ndarray:
        return self.phi(x, d) if letter == "a" else self.psi(x, d)

    # --- norms for thresholding (docs/model.md §2) -------------------------------
    @cached_property
    def norm_phi(self) -> float:
        """``||N_j||``: the autocorrelation of N_j is N_2j shifted by j."""
        return float(np.sqrt(bspline(2 * self.order, float(self.order))))

    @cached_property
    def norm_psi(self) -> float:
        j, q = self.order, self.q
        k = np.arange(len(q))
        gram = bspline(2 * j, j + k[:, None] - k[None, :]) / 2.0
        return float(np.sqrt(q @ gram @ q))

    def norm(self, letter: str) -> float:
        return self.norm_phi if letter == "a" else self.norm_psi

    @lru_cache(maxsize=None)
    def analysis_norm(self, letter: str, level: int) -> float:
        """``||f||_2`` of the filter that gives a level-``level`` coefficient of part ``letter`` from the voxels along
        one axis: ``dec_lo`` cascaded ``level - 1`` times (each upsampled by 2 more), then ``dec_lo`` or ``dec_hi``.
        White noise of deviation sigma gives a band's coefficients the deviation sigma times the product over its
        three axes (docs/model.md §2, noise); the B-spline banks are not orthonormal, so these differ by band."""
        taps = np.ones(1)
        for step in range(level):
            last = self.bank["dec_hi" if letter == "d" and step == level - 1 else "dec_lo"]
            spread = np.zeros((len(last) - 1) * 2 ** step + 1)
            spread[::2 ** step] = last
            taps = np.convolve(taps, spread)
        return float(np.linalg.norm(taps))

    # --- Fourier transforms (docs/splatting.md §1), F(w) = int f e^{-iwx} dx ---------
    def fourier_phi(self, w) -> np.ndarray:
        w = np.asarray(w, float)
        half = w / 2
        sinc = np.sinc(half / np.pi)  # sin(w/2)/(w/2), 1 at w = 0
        return (np.exp(-1j * half) * sinc) ** self.order

    def fourier_psi(self, w) -> np.ndarray:
        w = np.asarray(w, float)
        k = np.arange(len(self.q))
        Q = np.exp(-1j * np.multiply.outer(w / 2, k)) @ self.q
        return 0.5 * Q * self.fourier_phi(w / 2)

    def fourier(self, letter: str, w) -> np.ndarray:
        return self.fourier_phi(w) if letter == "a" else self.fourier_psi(w)


def wavelet_for(name) -> SplineWavelet:
    """The :class:`SplineWavelet` for a name ('haar', 'linear', 'quadratic', 'cubic') or order."""
    if isinstance(name, SplineWavelet):
        return name
    if isinstance(name, (int, np.integer)) and not isinstance(name, bool):
        return SplineWavelet(int(name))
    key = str(name).strip().lower()
    if key not in WAVELET_ORDERS:
        raise InputError(f"unknown wavelet {name!r}; choose one of {', '.join(WAVELET_ORDERS)}")
    return SplineWavelet(WAVELET_ORDERS[key])


def max_levels(shape) -> int:
    """Largest number of decomposition levels for a grid: floor(log2(min axis)) - 1."""
    return int(np.floor(np.log2(min(shape)))) - 1


# ----------------------------------------------------------------------------- piece polynomials
@lru_cache(maxsize=None)
def pieces(order: int, letter: str) -> tuple:
    """Piecewise-polynomial table of a prototype (phi for ``"a"``, psi for ``"d"``): ``(rate, coeffs)``.

    Piece i covers ``[i/rate, (i+1)/rate)`` (rate 1 for phi, whose knots are the integers; 2 for
    psi, whose knots are the half-integers) and there ``P(x) = sum_c coeffs[i, c] y^c`` with
    ``y = rate x - i`` in [0, 1).  Fitted from exact samples at Chebyshev nodes (interpolation of
    degree j - 1, exact up to rounding).  The one table of the prototypes: the exact footprint
    integrals (:mod:`clwave.splat.spatial`) and the wavelet-space ray tracer (:func:`piece_polynomials`)
    both read it.
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


def eval_pieces(order, letter, x) -> np.ndarray:
    """Evaluate a prototype from its :func:`pieces` (0 outside its half-open support)."""
    rate, coeffs = pieces(order, letter)
    xs = np.asarray(x, float) * rate
    piece = np.floor(xs)
    inside = (piece >= 0) & (piece < len(coeffs))
    idx = np.clip(piece, 0, len(coeffs) - 1).astype(np.intp)
    y = xs - idx
    out = coeffs[idx, -1]
    for c in range(coeffs.shape[1] - 2, -1, -1):
        out = out * y + coeffs[idx, c]
    return np.where(inside, out, 0.0)


@lru_cache(maxsize=None)
def knots(order: int, letter: str) -> np.ndarray:
    """Knots of a prototype: integers 0..j for phi, half-integers 0..2j-1 for psi."""
    rate = 1 if letter == "a" else 2
    return np.arange(SplineWavelet(order).support(letter) * rate + 1) / rate


def piece_polynomials() -> np.ndarray:
    """(70, 6) monomial coefficients of the prototypes' :func:`pieces` for orders 1, 2, 3, 4 and 6, as
    ``cl/raytrace/field_wavelet.h`` reads them (``PHI_ROW``, ``PSI_ROW``): the rows of ``N_j(s + r)``, r < j,
    for each order in turn (from row 0), then those of ``psi((s + c) / 2)``, c < 2 (2j - 1) (from row 16);
    each a polynomial in s on [0, 1) of degree j - 1, zero-padded to 6 coefficients."""
    orders = sorted(set(WAVELET_ORDERS.values()))
    rows = [np.pad(c, ((0, 0), (0, 6 - c.shape[1]))) for letter in "ad" for j in orders
            for c in [pieces(j, letter)[1]]]
    return np.ascontiguousarray(np.concatenate(rows))
