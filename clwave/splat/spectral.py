"""Footprint textures by projection slicing (paper §4.3, docs/splatting.md §1): the slice
``F(U u + V v)`` of a prototype's closed-form 3-D spectrum, sampled with NumPy or on the device
(``cl/splat/footprint.cl``), and turned into periodic samples by one inverse real FFT."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pyopencl.array as cla
import scipy.fft

from ..device import programs
from ..device.kernels import BUFFER, Kernel
from ..errors import InputError
from ..model.bspline import SplineWavelet, wavelet_for


# ----------------------------------------------------------------------------- Fourier factors
@lru_cache(maxsize=None)
def psi_poly(order: int) -> tuple:
    """The tap sum of psi's centred transform as a polynomial: ``(coeffs, imaginary, moments)``.

    ``sum_k q_k e^(-i n_k t) = (-i)^imaginary s^M P(s^2)`` with ``s = sin t``,
    ``n_k = 2k - (3j - 2)`` and ``P = sum_r coeffs[r] (s^2)^r``.  The factor ``s^M`` is psi's
    M vanishing moments (``Q`` has the root ``(1 - e^(-iw))^M``): M = j for CDF(j, j), 2 for the
    lifted order-6 bank (docs/model.md §2).
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
    moments = int(np.argmax(np.abs(power) > 1e-12))
    rest = power[moments:]
    if moments == 0 or np.max(np.abs(rest[1::2]), initial=0.0) > 1e-12:
        raise InputError("footprints need psi with a vanishing mean")  # pragma: no cover
    return tuple(rest[0::2]), imaginary, moments


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
        phi: num = sin x, poly = 1;   psi: num = sin^2 x, poly = P(sin^2 x)  (:func:`psi_poly`)

    (psi with M < j vanishing moments: num = sin x, poly = sin^M x P(sin^2 x).)

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
        self.coeffs, self.imaginary, self.moments = psi_poly(order) if letter == "d" else (None, False, 0)

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
        elif self.moments == self.order:
            num = s * s
            poly = _poly(self.coeffs, num)
        else:
            num = s
            poly = _poly(self.coeffs, s * s) * s ** self.moments
        small = _small_positions(x, self.a_, self.b_, self.ku, self.kv[r0:r1])
        if len(small[0]):
            xs = x[small]
            sinc = 1.0 - xs * xs / 6.0  # sin(x)/x to 1e-17 for |x| < 1e-4
            num[small] = sinc if num is s else sinc * s[small]
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

    >>> from clwave.model.bspline import SplineWavelet
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


def slice_plan(wav, key, m, d_xyz, u, v, wu, wv) -> tuple:
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


def fft_texture(wav, key, m, d_xyz, u, v, nu, nv, wu, wv, workers=-1, block=16384) -> np.ndarray:
    """Period-(W_u, W_v) samples of T at ``a = p h_u``, ``b = q h_v`` in FFT order, (nv, nu)."""
    ku = np.arange(nu // 2 + 1, dtype=float)         # U = ku du, the rfft half
    kv = np.fft.fftfreq(nv, 1.0 / nv)                # V = kv dv, FFT order
    scale, plan = slice_plan(wav, key, m, d_xyz, u, v, wu, wv)
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


_SPECTRA = Kernel("footprint_spectra", ("group_tex", BUFFER), ("tex_size", BUFFER), ("tex_rate", BUFFER),
                  ("poly", BUFFER), ("out", BUFFER))
SPECTRUM_GROUP = 16  # work-items per work-group of cl/splat/footprint.cl, each group within one texture


SPECTRUM_BLOCK = 16  # columns per work-item: the kernel's float16
#: arrays kept for the next call to write over (a view's spectra, samples, nodes, pool) are allocated this much larger
#: than the call that makes them needs, so that somewhat larger ones fit too
WORK_ROOM = 1.25


def device_spectra(cc, order: int, plans, quasi=False, work=None) -> list:
    """Half-spectra of textures on an OpenCL device (``cl/splat/footprint.cl``), in one launch.

    ``plans`` holds ``(scale, axes, nu, nv)`` per texture (:func:`slice_plan`); each spectrum
    comes back as an ``(nv, nu // 2 + 1)`` complex64 view in FFT row order, scaled for
    ``irfft2`` (float32 throughout: the textures are within ~1e-6 of their peak from those of
    the float64 NumPy spectra).  ``quasi``: of the textures' quasi-interpolants along rows and columns
    (:func:`clwave.splat.perspective.quasi_interpolant`, periodic), for perspective views.
    ``work``: a dict in which the spectra's host array (and on a CPU device, whose buffers are host memory, the
    device's) is kept and written over by the next call that fits it: fresh memory costs its first touch (a view's
    spectra are tens of MB, docs/splatting.md §8); the spectra returned are then views of it, valid until that call.
    """
    if not plans:
        return []
    coeffs, imaginary, moments = psi_poly(order)
    if moments < order:  # the kernel sums s^M P(s^2) in Chebyshev form: its power form is ill-conditioned
        power = np.zeros(moments + 2 * len(coeffs) - 1)
        power[moments::2] = coeffs
        coeffs = np.polynomial.chebyshev.poly2cheb(power)
    sizes, rates, group_tex, first = [], [], [], 0
    for t, (scale, axes, nu, nv) in enumerate(plans):
        rate, psi = np.zeros(8), 0  # absent axes: phi at rate 0, a factor of 1
        for a, (letter, alpha, beta) in enumerate(axes):
            rate[2 * a: 2 * a + 2] = alpha / _RATE[letter], beta / _RATE[letter]
            psi |= (letter == "d") << a
        phase = scale * nu * nv * (-1j) ** (imaginary * bin(psi).count("1"))
        rate[6:] = phase.real, phase.imag
        blocks = -(-(nu // 2 + 1) // SPECTRUM_BLOCK)
        sizes.append((first, nv, blocks, psi | nu << 3))
        rates.append(rate)
        groups = -(-nv * blocks // SPECTRUM_GROUP)
        group_tex += [t] * groups
        first += groups * SPECTRUM_GROUP
    q, total, room = cc.queue, first * SPECTRUM_BLOCK, 1.0 if work is None else WORK_ROOM
    work = {} if work is None else work
    if work.get("host", np.zeros(0)).size < total:  # room for a somewhat larger call, which then fits
        work["host"] = np.empty(int(room * total), np.complex64)
    out = work.get("device")
    if out is None or out.size < total:
        out = cla.empty(q, work["host"].shape, np.complex64)
        if cc.info.kind == "CPU":
            work["device"] = out
    defines = {"CLW_ORDER": order, "CLW_TERMS": len(coeffs), "CLW_MOMENTS": moments}
    kernels = programs.build(cc, ["splat/footprint.cl"], {**defines, "CLW_QUASI": None} if quasi else defines)
    _SPECTRA(kernels, q, (first,), (SPECTRUM_GROUP,), group_tex=cc.upload(np.array(group_tex, np.int32)),
             tex_size=cc.upload(np.array(sizes, np.int32)), tex_rate=cc.upload(np.array(rates, np.float32)),
             poly=cc.upload(np.array(coeffs, np.float32)), out=out)
    spectra = out[:total].get(ary=work["host"][:total])
    return [spectra[f * SPECTRUM_BLOCK: (f + nv * blocks) * SPECTRUM_BLOCK].reshape(nv, -1)[:, : nu // 2 + 1]
            for (f, nv, blocks, _), (_, _, nu, _) in zip(sizes, plans)]
