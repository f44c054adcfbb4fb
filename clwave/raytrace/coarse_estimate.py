"""What the staged tracer's coarse frames lack, in the image (docs/raytracing.md §9): the approximation's field
energy from its coefficients (held by the coarse stage), the share of it that survives a view's line integration
from the X-ray frame's own image, against the same share for the details, which are not read.

The field ``f = sum c_k phi(y - k)`` (y in units of the approximation's lattice) has energy ``<c, c * G>``, channels
summed, with the B-splines' overlap ``G(m) = prod over axes of N_2j(j + m_axis)`` (their autocorrelation, separable
and zero beyond ``|m| < j``: a filter of 2j - 1 taps per axis).  Its line integrals are what an X-ray frame of the
coarse stage shows (the coarse stage has no content clamp), so their energy, the integral of their squares over
the plane across the rays, is the sum of the image's squares times a pixel's area, taken to lattice units
(:func:`line_energy`): no autocorrelation of the coefficients is needed.
"""

from __future__ import annotations

import numpy as np
import scipy.special
from scipy.ndimage import correlate1d

from ..model.bspline import bspline
from ..model.wavelet import ChannelGroup


def approximation_grid(group: ChannelGroup) -> np.ndarray:
    """A group's approximation band as a dense (C, z, y, x) array of its values' type (the coefficients not kept
    0)."""
    band, sl = group.bands[0], group.band_slices()[0]
    grid = np.zeros((group.values.shape[0], band.size), group.values.dtype)
    grid[:, group.all_positions()[sl] - band.start] = group.values[:, sl]
    return grid.reshape(-1, *band.shape)


def field_energy(grid: np.ndarray, order: int) -> float:
    """``<c, c * G>``: the energy of the approximation's field from its coefficients (C, z, y, x), channels
    summed (filtered in their type, float32 from a file, and summed in float64)."""
    taps = bspline(2 * order, order + np.arange(1 - order, order))
    smooth = grid
    for axis in (1, 2, 3):
        smooth = correlate1d(smooth, taps, axis=axis, mode="constant")
    return float(np.sum(grid * smooth, dtype=np.float64))


def line_energy(image: np.ndarray, view, lattice, levels: int) -> float:
    """The energy of the approximation's line integrals along ``view``'s rays in its lattice's units, channels
    summed, from the coarse stage's X-ray image (H, W, C) of ``view`` (the image's own, reduced view).  The stage
    renders ``2^(-3L/2) f`` at world ``x``, ``y = M x`` with ``M = diag(1 / lattice)`` (``lattice``: the lattice's
    world spacing, z y x; docs/model.md §4), so a pixel is ``2^(-3L/2) / |M n|`` times the lattice line integral
    through it, and a world area across the rays is ``det M / |M n|`` of lattice area: the energy is
    ``2^(3L) |M n| det M`` times the world one, ``sum I² · pixel area``.  A perspective view takes its pixels' area
    at the target and its central ray's direction; a view that crops the field counts the part it shows."""
    m = 1.0 / np.asarray(lattice, float)
    area = view.pixel ** 2 * (view.slope[0] / view.slope[1] if view.perspective else 1.0)  # rectangular pixels
    world = float(np.sum(np.square(image, dtype=np.float64))) * area
    return world * 2.0 ** (3 * levels) * float(np.linalg.norm(view.n[::-1] * m)) * float(np.prod(m))


def detail_share(wavelet, direction) -> float:
    """The largest, over the seven detail types of the coarsest level, of the share of a detail band's energy
    that survives the line integrals along ``direction`` where its coefficients are uncorrelated (white)
    (:func:`white_share`).  A finer level l keeps ``2^(l - L)`` of the coarsest level's share (its functions
    ``2^(L - l)`` times shorter along the ray), so this bounds every detail band of white coefficients; a type
    whose wavelet factor lies along the ray keeps none (its vanishing moments)."""
    return max(white_share(wavelet, direction, key) for key in ("aad", "ada", "daa", "add", "dad", "dda", "ddd"))


def white_share(wavelet, direction, key) -> float:
    """The share of the energy of a band of type ``key`` (letters z y x, ``a`` for phi) that survives the line
    integrals along ``direction`` (lattice units) where its coefficients are uncorrelated (white): the line integral
    through 0 of its function's autocorrelation along the ray over its value at 0, in lattice cells."""
    j, q = wavelet.order, wavelet.q
    shifts = np.subtract.outer(np.arange(len(q)), np.arange(len(q))).reshape(-1)
    weights = np.outer(q, q).reshape(-1) / 2.0

    def autocorr(letter, x):  # of phi = N_j, or of psi = sum_k q_k N_j(2y - k)
        if letter == "a":
            return bspline(2 * j, j + x)
        return np.sum(weights * bspline(2 * j, j + 2 * np.asarray(x)[..., None] + shifts), axis=-1)

    d = np.asarray(direction, float) / np.linalg.norm(direction)
    reach = (2 * j - 1) / np.max(np.abs(d))  # beyond it every factor along the ray is 0
    nodes, gauss = scipy.special.roots_legendre(256)  # numpy's leggauss solves a dense eigenproblem
    t = reach * nodes
    along = np.prod([autocorr(letter, t * d[a]) for a, letter in enumerate(key)], axis=0)
    at_zero = np.prod([autocorr(letter, np.zeros(1))[0] for letter in key])
    return float(np.sum(along * gauss)) * reach / at_zero
