"""What the staged tracer's coarse frames lack, in the image (docs/raytracing.md §9): the approximation's field
energy and its share that survives a view's line integration, from the approximation's coefficients (held by
the coarse stage), against the same share for the details, which are not read.

Both from the coefficients' autocorrelation ``A(m) = sum over k and channels of c_k c_(k+m)``, in units of the
approximation's lattice: the field ``f = sum c_k phi(y - k)`` has energy ``sum_m A(m) G(m) = <c, c * G>``, with
the B-splines' overlap ``G(m) = prod over axes of N_2j(j + m_axis)`` (their autocorrelation, separable and zero
beyond ``|m| < j``: a filter of 2j - 1 taps per axis, no autocorrelation needed), and its line integrals
along a unit direction d have energy ``sum_m A(m) R_d(m)``, ``R_d(m) = integral of G(m + t d) dt`` (the integral
of the projection's square: the projections of phi(y - k) and phi(y - k') overlap as the autocorrelation's line
integral through their offset, the Fourier slice theorem in space).
"""

from __future__ import annotations

import numpy as np
import scipy.fft
from scipy.ndimage import correlate1d

from ..model.bspline import bspline
from ..model.wavelet import ChannelGroup

GAUSS = np.polynomial.legendre.leggauss(48)  # nodes and weights on [-1, 1]: the line integrals


def approximation_grid(group: ChannelGroup) -> np.ndarray:
    """A group's approximation band as a dense (C, z, y, x) float64 array (the coefficients not kept 0)."""
    band, sl = group.bands[0], group.band_slices()[0]
    grid = np.zeros((group.values.shape[0], band.size))
    grid[:, group.all_positions()[sl] - band.start] = group.values[:, sl]
    return grid.reshape(-1, *band.shape)


def autocorrelation(grid: np.ndarray) -> np.ndarray:
    """``A(m)`` of coefficients (C, z, y, x), summed over their channels, offsets ``m`` from ``-(n - 1)`` to
    ``n - 1`` per axis (index ``m + n - 1``): a channel's power spectrum at a time, on transform sizes of small
    primes at least ``2n - 1`` (no periodic copy reaches those offsets)."""
    size = [scipy.fft.next_fast_len(2 * n - 1, real=True) for n in grid.shape[1:]]
    power = 0.0
    for channel in grid:
        spectrum = scipy.fft.rfftn(channel, size, workers=-1)
        power = power + (spectrum.real ** 2 + spectrum.imag ** 2)
    out = scipy.fft.irfftn(power, size, workers=-1)
    return out[np.ix_(*(np.arange(-(n - 1), n) % s for n, s in zip(grid.shape[1:], size)))]


def field_energy(grid: np.ndarray, order: int) -> float:
    """``<c, c * G>``: the energy of the approximation's field from its coefficients (C, z, y, x), channels
    summed."""
    taps = bspline(2 * order, order + np.arange(1 - order, order))
    smooth = grid
    for axis in (1, 2, 3):
        smooth = correlate1d(smooth, taps, axis=axis, mode="constant")
    return float(np.sum(grid * smooth))


def projected_energy(autocorr: np.ndarray, order: int, direction) -> float:
    """``sum_m A(m) R_d(m)``: the energy of the approximation's line integrals along the unit ``direction``
    (z, y, x), for the offsets whose line meets the autocorrelation's support ``(-j, j)^3``."""
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    centre = np.array([(n - 1) // 2 for n in autocorr.shape])
    main = int(np.argmax(np.abs(d)))  # the offsets near the line through 0: along its main axis, then across
    near = np.arange(-2 * order - 1, 2 * order + 2)
    along = np.arange(autocorr.shape[main]) - centre[main]
    across = {b: np.rint(along * d[b] / d[main])[:, None] + near for b in range(3) if b != main}
    b, c = sorted(across)
    m = np.zeros((len(along), len(near), len(near), 3))
    m[..., main] = along[:, None, None]
    m[..., b], m[..., c] = across[b][:, :, None], across[c][:, None, :]
    m = m.reshape(-1, 3)
    m = m[np.all(np.abs(m) <= centre, axis=1)]
    lo, hi = np.full(len(m), -np.inf), np.full(len(m), np.inf)
    for a in range(3):  # the t where |m_a + t d_a| < j on every axis
        if abs(d[a]) < 1e-12:
            inside = np.abs(m[:, a]) < order
            lo[~inside], hi[~inside] = 0.0, 0.0
            continue
        t1, t2 = (-order - m[:, a]) / d[a], (order - m[:, a]) / d[a]
        lo, hi = np.maximum(lo, np.minimum(t1, t2)), np.minimum(hi, np.maximum(t1, t2))
    meets = hi > lo
    m, lo, hi = m[meets], lo[meets], hi[meets]
    nodes, weights = GAUSS
    t = (lo + hi)[:, None] / 2 + (hi - lo)[:, None] / 2 * nodes  # (M, nodes)
    g = np.ones_like(t)
    for a in range(3):
        g *= bspline(2 * order, order + m[:, a, None] + t * d[a])
    r = np.sum(g * weights, axis=1) * (hi - lo) / 2
    index = tuple((m + centre).astype(int).T)
    return float(np.sum(autocorr[index] * r))


def detail_share(wavelet, direction) -> float:
    """The largest, over the seven detail types of the coarsest level, of the share ``R_d(0) / G(0)`` of a
    detail band's energy that survives the line integrals along ``direction`` where its coefficients are
    uncorrelated (white): the wavelets' autocorrelations along the ray.  A finer level l keeps ``2^(l - L)`` of
    the coarsest level's share (its functions ``2^(L - l)`` times shorter along the ray), so this bounds every
    detail band of white coefficients; a type whose wavelet factor lies along the ray keeps none (its
    vanishing moments)."""
    j, q = wavelet.order, wavelet.q
    shifts = np.subtract.outer(np.arange(len(q)), np.arange(len(q))).reshape(-1)
    weights = np.outer(q, q).reshape(-1) / 2.0

    def autocorr(letter, x):  # of phi = N_j, or of psi = sum_k q_k N_j(2y - k)
        if letter == "a":
            return bspline(2 * j, j + x)
        return np.sum(weights * bspline(2 * j, j + 2 * np.asarray(x)[..., None] + shifts), axis=-1)

    d = np.asarray(direction, float) / np.linalg.norm(direction)
    reach = (2 * j - 1) / np.max(np.abs(d))  # beyond it every factor along the ray is 0
    nodes, gauss = np.polynomial.legendre.leggauss(256)
    t = reach * nodes
    best = 0.0
    for key in ("aad", "ada", "daa", "add", "dad", "dda", "ddd"):
        along = np.prod([autocorr(letter, t * d[a]) for a, letter in enumerate(key)], axis=0)
        at_zero = np.prod([autocorr(letter, np.zeros(1))[0] for letter in key])
        best = max(best, float(np.sum(along * gauss)) * reach / at_zero)
    return best
