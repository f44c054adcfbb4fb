"""Closed-form B-splines, the banks' filters (CDF(j, j), lifted CDF(6, 6)), offsets, norms and Fourier
transforms (docs/model.md §1-4 and docs/splatting.md §1)."""

import sys
from fractions import Fraction
from math import comb
from pathlib import Path

import numpy as np
import pytest

from clwave.model.bspline import SplineWavelet, bspline, bspline_derivative, bspline_explicit, max_levels, wavelet_for
from clwave.errors import InputError

ORDERS = (1, 2, 3, 4, 6)


@pytest.mark.parametrize("j", ORDERS)
def test_cox_de_boor_equals_truncated_power_form(j):
    x = np.linspace(-1.5, j + 1.5, 2001)
    assert np.max(np.abs(bspline(j, x) - bspline_explicit(j, x))) < 1e-12


@pytest.mark.parametrize("j", (2, 3, 4, 6))
def test_derivative_matches_finite_differences(j):
    x = np.linspace(0.013, j - 0.013, 301)
    x = x[np.abs(x - np.round(x)) > 1e-3]  # away from the knots (N_2' jumps there)
    h = 1e-6
    fd = (bspline(j, x + h) - bspline(j, x - h)) / (2 * h)
    assert np.max(np.abs(bspline_derivative(j, x) - fd)) < 1e-6


@pytest.mark.parametrize("j", ORDERS)
def test_two_scale_relation_and_partition_of_unity(j):
    w = SplineWavelet(j)
    x = np.linspace(-1, j + 1, 4097)
    refined = sum(pk * bspline(j, 2 * x - k) for k, pk in enumerate(w.p))
    assert np.max(np.abs(refined - bspline(j, x))) < 1e-13
    xs = np.linspace(j, j + 5, 301)
    assert np.allclose(sum(bspline(j, xs - i) for i in range(0, j + 6)), 1.0, atol=1e-13)


def test_wavelet_taps_match_math_table():
    assert np.allclose(SplineWavelet(2).q, np.array([-1, -2, 6, -2, -1]) / 4)
    assert np.allclose(SplineWavelet(3).q, np.array([3, 9, -7, -45, 45, 7, -9, -3]) / 32)
    assert np.allclose(SplineWavelet(4).q, np.array([-5, -20, -1, 96, 70, -280, 70, 96, -1, -20, -5]) / 128)
    assert np.allclose(SplineWavelet(4).p, np.array([1, 4, 6, 4, 1]) / 8)


@pytest.mark.parametrize("j", ORDERS)
def test_psi_support_and_vanishing_moments(j):
    w = SplineWavelet(j)
    x = np.linspace(-2, 2 * j + 1, 40001)
    dx = x[1] - x[0]
    psi = w.psi(x)
    outside = (x < 0) | (x > 2 * j - 1)
    assert np.all(psi[outside] == 0)
    # CDF(j, j) psi has j vanishing moments (Haar: 1); the lifted order-6 psi keeps 2 (docs/model.md §2)
    for power in range({1: 1, 6: 2}.get(j, j)):
        moment = np.sum(psi * x ** power) * dx
        assert abs(moment) < 1e-6 * (2 * j) ** power
    if j == 6:  # and no more: its second moment about the centre is -0.8291
        assert abs(np.sum(psi * (x - 5.5) ** 2) * dx + 0.8291) < 1e-4


def test_quintic_bank_is_lifted_cdf66_and_exactly_biorthogonal():
    """The order-6 taps: CDF(6, 6) derived exactly (tools/order6_banks.py) and lifted by the documented s, and
    the four filters biorthogonal in exact rational arithmetic (sum_k h_k h~_{k+2n} = delta_n, ...)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
    from order6_banks import biorthogonal, cdf_dual
    p = [Fraction(comb(6, k), 32) for k in range(7)]
    pt, first = cdf_dual(6, 6)
    (q, _), _ = biorthogonal(p, 0, pt, first)
    s = [Fraction(v, 4096) for v in (1377, -3282, 1905, 1905, -3282, 1377)]
    lifted = [qk - sum(s[n] * p[k - 2 * n] for n in range(6) if 0 <= k - 2 * n <= 6) for k, qk in enumerate(q)]
    assert np.max(np.abs(SplineWavelet(6).q - np.array([float(v) for v in lifted]))) < 1e-15
    bank = SplineWavelet(6).bank  # arrays times 1/sqrt2; times 131072 sqrt2 they are integers
    h, ht, g, gt = ([Fraction(round(v * 131072 * np.sqrt(2)), 131072) for v in bank[k]]
                    for k in ("rec_lo", "dec_lo", "rec_hi", "dec_hi"))
    F = len(h)
    ht, gt = ht[::-1], gt[::-1]  # pywt stores the analysis filters reversed
    for a, b, want in ((h, ht, 2), (g, gt, 2), (h, gt, 0), (g, ht, 0)):
        for n in range(-F // 2, F // 2 + 1):
            dot = sum(a[k] * b[k + 2 * n] for k in range(F) if 0 <= k + 2 * n < F)
            assert dot == (want if n == 0 else 0), (n, dot)


def test_norms_match_math_table():
    assert [round(SplineWavelet(j).norm_phi, 4) for j in ORDERS] == [1.0, 0.8165, 0.7416, 0.6924, 0.6276]
    assert round(SplineWavelet(2).norm_psi, 4) == 0.8660
    assert round(SplineWavelet(4).norm_psi, 4) == 1.0606
    assert round(SplineWavelet(6).norm_psi, 4) == 1.4301
    # against a direct quadrature of psi^2
    for j in (4, 6):
        x = np.linspace(0, 2 * j - 1, 70001)
        assert abs(np.sqrt(np.trapezoid(SplineWavelet(j).psi(x) ** 2, x)) - SplineWavelet(j).norm_psi) < 1e-6


def test_offsets_match_math_table():
    table = {1: ([0, 0, 0, 0], [0, 0, 0, 0]), 2: ([-3, -9, -21, -45], [-3, -9, -21, -45]),
             3: ([-4, -12, -28, -60], [-6, -16, -36, -76]), 4: ([-7, -21, -49, -105], [-9, -25, -57, -121]),
             6: ([-11, -33, -77, -165], [-15, -41, -93, -197])}
    for j, (oa, od) in table.items():
        w = SplineWavelet(j)
        assert [w.offset("a", m) for m in (1, 2, 3, 4)] == oa
        assert [w.offset("d", m) for m in (1, 2, 3, 4)] == od


def test_banks_equal_pywavelets_biorthogonal_up_to_psi_sign():
    import pywt
    for j, name, sign in ((1, "bior1.1", 1), (2, "bior2.2", -1), (3, "bior3.3", 1)):
        ours, ref = SplineWavelet(j).pywt, pywt.Wavelet(name)
        assert np.allclose(ours.rec_lo, ref.rec_lo) and np.allclose(ours.dec_lo, ref.dec_lo)
        assert np.allclose(ours.rec_hi, sign * np.array(ref.rec_hi))


@pytest.mark.parametrize("j, tol", [(1, 2e-4), (2, 2e-5), (4, 1e-8), (6, 1e-8)])
@pytest.mark.parametrize("letter", ["a", "d"])
def test_fourier_transforms_match_fft_of_sampled_basis(j, tol, letter):
    """F(w) = int f e^{-iwx}: midpoint samples on [0, L), FFT, phase for the half-sample shift."""
    w = SplineWavelet(j)
    delta, n = 1.0 / 512, 16384  # period 32 > support
    x = (np.arange(n) + 0.5) * delta
    omega = 2 * np.pi * np.fft.fftfreq(n, d=delta)
    approx = delta * np.exp(-1j * omega * delta / 2) * np.fft.fft(w.prototype(letter, x))
    band = np.abs(omega) <= 30
    exact = w.fourier(letter, omega[band])
    assert np.max(np.abs(approx[band] - exact)) < tol
    assert abs(w.fourier(letter, np.array([0.0]))[0] - (1.0 if letter == "a" else 0.0)) < 1e-14


def test_wavelet_names_and_levels():
    assert wavelet_for("cubic").order == 4 and wavelet_for("Haar").order == 1 and wavelet_for(2).order == 2
    assert wavelet_for("quintic").order == 6 and wavelet_for(6).name == "quintic"
    with pytest.raises(InputError, match="unknown wavelet"):
        wavelet_for("bior4.4")
    assert max_levels((256, 256, 256)) == 7 and max_levels((2, 9, 9)) == 0 and max_levels((33, 40, 29)) == 3
