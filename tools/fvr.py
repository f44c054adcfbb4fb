"""Fourier volume rendering (Malzbender 1993; Totsuka & Levoy 1993), the X-ray peer of
tools/compare_peers.py: one 3-D FFT of the zero-padded volume, then per view a central slice
interpolated with a Kaiser-Bessel kernel and one inverse 2-D FFT."""

from __future__ import annotations

import math

import numpy as np
import scipy.fft
import scipy.special


KB_WIDTH = 6        # Kaiser-Bessel kernel width in grid points (Fourier volume rendering)


KB_OVERSAMPLING = 2


def _kb(y):
    """Kaiser-Bessel kernel (width KB_WIDTH grid points, Beatty et al. 2005 beta) at offsets y."""
    beta = math.pi * math.sqrt((KB_WIDTH / KB_OVERSAMPLING) ** 2 * (KB_OVERSAMPLING - 0.5) ** 2 - 0.8)
    arg = np.clip(1.0 - (2.0 * y / KB_WIDTH) ** 2, 0.0, None)
    return np.where(np.abs(y) <= KB_WIDTH / 2.0, scipy.special.i0(beta * np.sqrt(arg)), 0.0), beta


def _kb_hat(s, beta):
    """Fourier transform of the kernel at frequency s (cycles per grid point)."""
    z = np.sqrt((beta ** 2 - (math.pi * KB_WIDTH * s) ** 2).astype(complex))
    return (KB_WIDTH * np.sinh(z) / z).real


class FourierRenderer:
    """Fourier volume rendering: F(w) = sum_k f_k exp(-2 pi i w . x_k) on central slices.

    The 3-D spectrum is the non-uniform FFT of the samples (sinc-interpolated, i.e. band
    limited to the voxel Nyquist cube): pre-divide by the kernel transform, zero-pad to
    twice the size, FFT once; per view, interpolate the slice with the kernel.
    """

    def __init__(self, vol):
        self.vol = vol
        _, self.beta = _kb(np.zeros(1))
        self.shape = np.array(vol.shape)                        # (nz, ny, nx)
        self.grid = KB_OVERSAMPLING * self.shape
        k = [np.arange(N) - N // 2 for N in self.shape]            # centred sample indices per axis
        g = vol.data.astype(np.complex64)
        for axis in range(3):
            shape = [1, 1, 1]
            shape[axis] = -1
            g /= _kb_hat(k[axis] / self.grid[axis], self.beta).reshape(shape).astype(np.float32)
        padded = np.zeros(tuple(self.grid), np.complex64)
        # sample index k sits at grid index k mod G, so the FFT sums exp(-2 pi i k l / G)
        padded[np.ix_(*[np.mod(kk, G) for kk, G in zip(k, self.grid)])] = g
        del g
        self.flat = scipy.fft.fftn(padded, overwrite_x=True, workers=-1).ravel()
        # world position of centred index 0 per axis (z, y, x): x_k = c0 + k d
        spacing = np.array(vol.spacing, float)
        self.c0 = np.array(vol.origin[::-1], float) + (self.shape // 2 - (self.shape - 1) / 2.0) * spacing
        self.spacing = spacing

    def render(self, camera) -> np.ndarray:
        view = camera.view(self.vol)
        H, W = view.size
        p = view.pixel
        xi, eta = np.fft.fftfreq(W, p), np.fft.fftfreq(H, p)  # cycles per world unit, FFT order
        omega = xi[None, :, None] * view.u[::-1] + eta[:, None, None] * view.v[::-1]  # (H, W, 3) as (z, y, x)
        nu = omega * self.spacing                                   # cycles per sample
        inside = np.all(np.abs(nu) < 0.5, axis=-1)
        pos = nu * self.grid                                        # continuous grid index
        base = np.floor(pos).astype(np.int64) - KB_WIDTH // 2 + 1
        value = np.zeros((H, W), np.complex128)
        weights = [[_kb(pos[..., a] - (base[..., a] + j))[0] for j in range(KB_WIDTH)] for a in range(3)]
        index = [[np.mod(base[..., a] + j, self.grid[a]) for j in range(KB_WIDTH)] for a in range(3)]
        for jz in range(KB_WIDTH):
            for jy in range(KB_WIDTH):
                wzy = weights[0][jz] * weights[1][jy]
                row = (index[0][jz] * self.grid[1] + index[1][jy]) * self.grid[2]
                for jx in range(KB_WIDTH):
                    value += wzy * weights[2][jx] * np.take(self.flat, row + index[2][jx])
        # phase of the sample origin relative to the image centre, and the pixel-centre offsets
        value *= np.exp(-2j * np.pi * (omega @ (self.c0 - view.target[::-1]))) * np.prod(self.spacing)
        value = np.where(inside, value, 0.0)
        s0 = (0.5 - W / 2.0) * p
        t0 = (H / 2.0 - 0.5) * p
        value *= np.exp(2j * np.pi * (xi[None, :] * s0 + eta[:, None] * t0))
        image = np.fft.fft(np.fft.ifft(value, axis=1) * W, axis=0) / (W * p * H * p)
        return image.real.astype(np.float32)
