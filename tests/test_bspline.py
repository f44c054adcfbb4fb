"""Closed-form B-splines, CDF(j, j) filters, offsets, norms and Fourier transforms
(docs/model.md §1-4 and docs/splatting.md §1)."""

import numpy as np
import pytest

from clwave.model.bspline import SplineWavelet, bspline, bspline_derivative, bspline_explicit, max_levels, wavelet_for
from clwave.errors import InputError

ORDERS = (1, 2, 3, 4)


@pytest.mark.parametrize("j", ORDERS + (6,))
def test_cox_de_boor_equals_truncated_power_form(j):
    x = np.linspace(-1.5, j + 1.5, 2001)
    assert np.max(np.abs(bspline(j, x) - bspline_explicit(j, x))) < 1e-12


@pytest.mark.parametrize("j", (2, 3, 4))
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
    for power in range(j if j > 1 else 1):  # CDF(j, j) psi has j vanishing moments (Haar: 1)
        moment = np.sum(psi * x ** power) * dx
        assert abs(moment) < 1e-6 * (2 * j) ** power


def test_norms_match_math_table():
    assert [round(SplineWavelet(j).norm_phi, 4) for j in ORDERS] == [1.0, 0.8165, 0.7416, 0.6924]
    assert round(SplineWavelet(2).norm_psi, 4) == 0.8660
    assert round(SplineWavelet(4).norm_psi, 4) == 1.0606
    # against a direct quadrature of psi^2
    x = np.linspace(0, 7, 70001)
    assert abs(np.sqrt(np.trapezoid(SplineWavelet(4).psi(x) ** 2, x)) - SplineWavelet(4).norm_psi) < 1e-6


def test_offsets_match_math_table():
    table = {1: ([0, 0, 0, 0], [0, 0, 0, 0]), 2: ([-3, -9, -21, -45], [-3, -9, -21, -45]),
             3: ([-4, -12, -28, -60], [-6, -16, -36, -76]), 4: ([-7, -21, -49, -105], [-9, -25, -57, -121])}
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


@pytest.mark.parametrize("j, tol", [(1, 2e-4), (2, 2e-5), (4, 1e-8)])
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
    with pytest.raises(InputError, match="unknown wavelet"):
        wavelet_for("bior4.4")
    assert max_levels((256, 256, 256)) == 7 and max_levels((2, 9, 9)) == 0 and max_levels((33, 40, 29)) == 3
