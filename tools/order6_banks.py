#!/usr/bin/env python3
"""Choosing clwave's order-6 (quintic B-spline) filter bank by numbers (docs/model.md §2).

    python tools/order6_banks.py [--size 64] [--levels 3] [--scan FILE]

Every candidate synthesises with the order-6 B-spline ``N_6`` (p_k = 2^-5 C(6, k)) and a spline
wavelet ``psi = sum_k q_k N_6(2x - k)``, as the paper's; they differ in ``psi`` and in the duals:

- ``CDF(6, Nt)``, Nt = 2 ... 12: Cohen-Daubechies-Feauveau, duals derived exactly here (fractions);
- ``CW6``: Chui-Wang (semi-orthogonal), IIR duals: its row gives the dual taps a truncation needs
  for 1e-6 (the analysis here is exact, periodic);
- ``CDF(6, 6)+L``: CDF(6, 6) lifted by ``psi <- psi - sum_{n=0..5} s_n N_6(x - n)`` (support kept at
  [0, 11]; symmetric, zero-sum s chosen to minimise the condition number, rounded to multiples of
  2^-12); its duals are FIR, p~ the alternating flip of the lifted q (17 taps, as CDF(6, 6)).

For each: the support of psi (footprint size, brick halo), the analysis filter length, the
condition number of the 4-level basis (unit-norm functions, continuous L2, periodic 256), and the
relative continuous-L2 error of the model after thresholding (approximation band first, then details
by |c| ||basis||, as ``WaveletVolume.threshold``) with the approximation band only (a-only) and at
1, 3, 5, 10 % kept, on hydrogen, Shepp-Logan
and the MNI152 MRI (if nilearn is installed).  The transform here is periodic, by dense matrices per
axis (the data have empty margins, so periodic equals zero extension up to the wrap).
"""

from __future__ import annotations

import argparse
import sys
from fractions import Fraction
from math import comb
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout

import clwave  # noqa: E402
from clwave.model.bspline import bspline  # noqa: E402

J = 6
P = np.array([comb(J, k) for k in range(J + 1)]) / 2.0 ** (J - 1)


# ----------------------------------------------------------------------------- exact CDF(6, Nt) taps
def _mul(a, b):
    out = [Fraction(0)] * (len(a) + len(b) - 1)
    for i, x in enumerate(a):
        for k, y in enumerate(b):
            out[i + k] += x * y
    return out


def cdf_dual(n: int, nt: int) -> tuple:
    """Exact p~ of CDF(n, nt) as fractions, index range [1 - nt, n + nt - 1] (centred on n/2):
    p~(z) = 2 ((1+z)/2)^nt z^-nt/2 sum_{i<l} C(l-1+i, i) (-(1-z)^2 / 4z)^i, l = (n + nt)/2."""
    ell = (n + nt) // 2
    half = [Fraction(1, 2), Fraction(1, 2)]
    lowpass = [Fraction(2)]
    for _ in range(nt):
        lowpass = _mul(lowpass, half)
    # sum_i C(l-1+i, i) (-1)^i (1-z)^(2i) z^(l-1-i) / 4^i: a polynomial of degree 2(l-1)
    total = [Fraction(0)] * (2 * ell - 1)
    for i in range(ell):
        term = [Fraction(comb(ell - 1 + i, i) * (-1) ** i, 4 ** i)]
        for _ in range(2 * i):
            term = _mul(term, [Fraction(1), Fraction(-1)])
        for k, c in enumerate(term):
            total[k + ell - 1 - i] += c
    taps = _mul(lowpass, total)  # centred at nt/2 + l - 1; shift to n/2
    first = n // 2 - (len(taps) - 1) // 2
    assert first == 1 - nt
    return taps, first


def biorthogonal(p, p_first, pt, pt_first) -> tuple:
    """q, q~ from p, p~ (q_k = (-1)^k p~_{c-k}, q~_k = (-1)^k p_{c-k}, c = last index of p~ + p_first),
    as (values, first index)."""
    c = pt_first + len(pt) - 1 + p_first
    q = [(-1) ** (c - i) * x for i, x in zip(range(pt_first, pt_first + len(pt)), pt)][::-1]
    qt = [(-1) ** (c - i) * x for i, x in zip(range(p_first, p_first + len(p)), p)][::-1]
    return (q, c - (pt_first + len(pt) - 1)), (qt, c - (p_first + len(p) - 1))


def chui_wang_q() -> np.ndarray:
    n = np.arange(3 * J - 1)
    return np.array([(-1) ** k * 2.0 ** (1 - J) * sum(comb(J, i) * bspline(2 * J, k - i + 1) for i in range(J + 1))
                     for k in n])


# ----------------------------------------------------------------------------- periodic machinery
def gram_kernel() -> np.ndarray:
    """<N_6(x - i), N_6(x - i - d)> = N_12(6 + d), d = -5 .. 5."""
    return bspline(2 * J, J + np.arange(-J + 1, J))


def circulant(taps, first, n, step) -> np.ndarray:
    """(n, n // step) matrix of x -> child l = step k + first + i (mod n) with weight taps[i]."""
    out = np.zeros((n, n // step))
    for k in range(n // step):
        for i, t in enumerate(taps):
            out[(step * k + first + i) % n, k] += t
    return out


def synthesis(q, n) -> np.ndarray:
    """One level: [coarse | detail] -> fine B-spline coefficients (L2 filters p/√2, q/√2)."""
    return np.hstack([circulant(P / np.sqrt(2), 0, n, 2), circulant(np.asarray(q, float) / np.sqrt(2), 0, n, 2)])


def gram(n) -> np.ndarray:
    return circulant(gram_kernel(), -J + 1, n, 1)


def condition(q, n=256, levels=4) -> float:
    """Riesz ratio sqrt(lambda_max / lambda_min) of the unit-normalised multilevel basis."""
    basis = np.eye(n)
    size = n
    blocks = []
    for _ in range(levels):
        s = synthesis(q, size)
        blocks.append(basis @ s[:, size // 2:])  # this level's wavelets in fine coefficients
        basis = basis @ s[:, :size // 2]
        size //= 2
    S = np.hstack([basis] + blocks[::-1])
    M = S.T @ gram(n) @ S
    d = 1 / np.sqrt(np.diag(M))
    ev = np.linalg.eigvalsh(M * d[:, None] * d[None, :])
    return float(np.sqrt(ev[-1] / ev[0]))


def norms(q) -> tuple:
    g = gram(64)
    s = synthesis(q, 64)
    e_phi, e_psi = s[:, 0], s[:, 32]
    return float(np.sqrt(e_phi @ g @ e_phi)), float(np.sqrt(e_psi @ g @ e_psi))


def dual_length(q, n=256, tol=1e-6) -> int:
    """Taps of the widest analysis row above tol times its largest (the FIR length, or a truncation's)."""
    a = np.linalg.inv(synthesis(q, n))
    rows = np.roll(np.abs(a[[0, n // 2]]), n // 2, axis=1)  # centred: the rows wrap around
    return int(max(np.ptp(np.nonzero(r > tol * r.max())[0]) + 1 for r in rows))


# ----------------------------------------------------------------------------- thresholding on data
class Transform:
    """Separable periodic multilevel transform of a cube by dense per-axis matrices."""

    def __init__(self, q, n, levels):
        self.levels = levels
        self.syn = [synthesis(q, n >> m) for m in range(levels)]
        self.ana = [np.linalg.inv(s) for s in self.syn]
        self.nphi, self.npsi = norms(q)

    @staticmethod
    def _axes(mat, x, box):
        for axis in range(3):
            sl = tuple(slice(0, b) for b in box)
            part = np.moveaxis(x[sl], axis, 0)
            x[sl] = np.moveaxis(np.tensordot(mat, part, axes=(1, 0)), 0, axis)
        return x

    def forward(self, x) -> np.ndarray:
        x = x.astype(np.float64).copy()
        for m in range(self.levels):
            self._axes(self.ana[m], x, [s >> m for s in x.shape])
        return x

    def inverse(self, c) -> np.ndarray:
        c = c.copy()
        for m in reversed(range(self.levels)):
            self._axes(self.syn[m], c, [s >> m for s in c.shape])
        return c

    def importance_weights(self, shape) -> tuple:
        """Per-coefficient ||basis|| (product of the 1-D norms) and the approximation-band mask, for the
        Mallat layout: along an axis, index i is a level-m detail where n >> m <= i < n >> (m - 1)."""
        scale = [np.array([max(m for m in range(self.levels + 1) if i < n >> m) for i in range(n)])
                 for n in shape]
        s = np.meshgrid(*scale, indexing="ij")
        level = np.minimum(np.minimum(s[0], s[1]), s[2]) + 1
        w = np.ones(shape)
        for sa in s:
            w = w * np.where(sa == level - 1, self.npsi, self.nphi)
        return w, level == self.levels + 1


def l2(e) -> float:
    """Continuous L2 norm of the fine spline with coefficients e (periodic Gram, separable)."""
    g = gram_kernel()
    x = e
    for axis in range(3):
        x = sum(t * np.roll(x, i - J + 1, axis=axis) for i, t in enumerate(g))
    return float(np.sqrt(np.sum(x * e)))


def threshold_errors(tr: Transform, data, fractions) -> list:
    c = tr.forward(data)
    w, approx = tr.importance_weights(c.shape)
    ref = l2(data)
    importance = np.where(approx, np.inf, np.abs(c) * w).ravel()
    order = np.argsort(-importance, kind="stable")
    out = []
    for f in fractions:
        kept = np.zeros(c.size, bool)
        kept[order[:max(int(round(f * c.size)), int(approx.sum()))]] = True
        rec = tr.inverse(np.where(kept.reshape(c.shape), c, 0.0))
        out.append(l2(rec - data) / ref)
    return out


# ----------------------------------------------------------------------------- the candidates
def candidates() -> dict:
    out = {}
    for nt in (2, 4, 6, 8, 10, 12):
        pt, pt_first = cdf_dual(J, nt)
        assert sum(pt) == 2
        (q, _), _ = biorthogonal([Fraction(comb(J, k), 2 ** (J - 1)) for k in range(J + 1)], 0, pt, pt_first)
        out[f"CDF(6,{nt})"] = np.array([float(x) for x in q])
    out["CW6"] = chui_wang_q()
    out["CDF(6,6)+L"] = lifted(out["CDF(6,6)"])
    return out


def lift(q, s2) -> np.ndarray:
    """psi - sum_{n=0..5} s_n N_6(x - n), s symmetric (s0, s1, s2, s2, s1, s0) with zero sum (psi keeps its
    vanishing mean, and by symmetry its first moment): q[2n + i] -= s_n p_i."""
    s3 = np.array([s2[0], s2[1], -s2[0] - s2[1]])
    s = np.concatenate([s3, s3[::-1]])
    out = np.array(q, float)
    for n, sn in enumerate(s):
        out[2 * n:2 * n + J + 1] -= sn * P
    return out


def lifted(q) -> np.ndarray:
    best = minimize(lambda s: condition(lift(q, s), n=128), np.zeros(2), method="Nelder-Mead",
                    options=dict(xatol=1e-6, fatol=1e-8))
    s = np.round(best.x * 4096) / 4096
    print(f"lifting s0, s1 = {s.tolist()} (x 4096: {(s * 4096).astype(int).tolist()}), s2 = -s0 - s1\n")
    return lift(q, s)


def datasets(size, scan) -> dict:
    out = {k: clwave.phantom(k, size).data for k in ("hydrogen", "shepp-logan")}
    if scan is not None:
        vol = clwave.load(scan)
        step = max(1, min(vol.shape) // size)
        d = vol.data[::step, ::step, ::step][:size, :size, :size].astype(np.float64)
        out["MNI152 MRI"] = np.pad(d, [(0, size - s) for s in d.shape])
    return {k: v - np.percentile(v, 1) * (k == "MNI152 MRI") for k, v in out.items()}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--levels", type=int, default=3)
    ap.add_argument("--scan", default=None, help="a volume file (default: nilearn's MNI152 T1 if installed)")
    args = ap.parse_args(argv)
    scan = args.scan
    if scan is None:
        try:
            import importlib.util
            spec = importlib.util.find_spec("nilearn")
            if spec is not None:
                scan = Path(spec.submodule_search_locations[0]) / \
                    "datasets/data/mni_icbm152_t1_tal_nlin_sym_09a_converted.nii.gz"
        except ImportError:
            pass
    data = datasets(args.size, scan)
    fractions = (0.01, 0.03, 0.05, 0.10)
    banks = candidates()
    print("| bank | psi support | analysis taps (1e-6) | cond (4 levels) | ||psi|| | "
          + " | ".join(f"{k}: a-only, {', '.join(f'{100 * f:g} %' for f in fractions)}" for k in data) + " |")
    print("|---|---|---|---|---|" + "---|" * len(data))
    for name, q in banks.items():
        nz = np.nonzero(np.abs(q) > 1e-12)[0]
        support = (nz[-1] + J) / 2 - nz[0] / 2
        tr = Transform(q, args.size, args.levels)
        errs = [threshold_errors(tr, d, (0.0,) + fractions) for d in data.values()]
        print(f"| {name} | {support:g} | {dual_length(q)} | {condition(q):.1f} | {tr.npsi:.4f} | "
              + " | ".join(" / ".join(f"{e:.3g}" for e in row) for row in errs) + " |", flush=True)


if __name__ == "__main__":
    main()
