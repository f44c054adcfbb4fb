"""Splatting's error estimate (docs/splatting.md §5): the image of the coefficients still to splat, predicted
from the coefficients themselves, without the final image.

Splatting is linear, so the error of a frame is exactly the image of the coefficients not yet splatted.  The
approximation band's footprints are smooth, of one sign and overlap their neighbours, so its rest is drawn signed,
each footprint as a Gaussian of the band's energy (:func:`band_energies`) and of its basis' variance; the detail
bands' footprints oscillate about zero, so their rest is drawn as an energy density, each footprint's energy spread
over its width.  Both on a grid of at most :data:`GRID` cells a side, blurred in Fourier space.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import fourier_gaussian

from ..model.geometry import band_lattice, fine_to_world, spacing_xyz
from .spectral import centred_fourier
from .tables import MAX_LEVELS

SLICE_POINTS = 12  # per side of the slice grid integrating a band's footprint energy (docs/splatting.md §5), per
#                   lattice step of the widest support S (its spectral lobes are 2 pi / (S max(d)) wide; 64 points at
#                   least), times the spacings' largest ratio, up to 8 times

GRID = 64  # cells per side, at most, of the estimate's maps (an image larger than this: cells of several pixels;
#            docs/splatting.md §5 has the rates at 64 and 256)
CHUNK = 1 << 18  # coefficients placed at once
DETAIL_WIDTH = 0.5  # the standard deviation of a level-m detail footprint's square, in 2^m voxels along u or v


def band_energies(wavelet, spacing, view) -> np.ndarray:
    """Image energy of a unit coefficient of each band code ``level * 8 + code`` (in world units at unit spacing;
    otherwise up to the factor ``(dx dy dz)^2``).

    Splatting is linear and a footprint is the projection of its function, so by the slice theorem a unit
    coefficient of band (m, key) draws the energy ``2^m I_key``, with ``I_key = ∫∫ prod_a |G_a(d_a (U u_a +
    V v_a))|^2 dU dV`` over the slice plane (G: :func:`~clwave.splat.spectral.centred_fourier`, d: the spacing);
    psi along the ray draws nothing.  A perspective view takes its axis (each coefficient's magnification is
    :class:`SplatEstimate`'s).
    """
    d_xyz = np.asarray(spacing, float)[::-1]
    reach = 16.0 * np.pi / float(np.min(d_xyz))  # |G|^2 is below 1e-6 of its peak beyond 16 pi / d
    points = max(64, SLICE_POINTS * max(wavelet.support("a"), wavelet.support("d")))
    grid = np.linspace(-reach, reach, int(points * min(8.0, np.ceil(np.max(d_xyz) / np.min(d_xyz)))))
    U, V = np.meshgrid(grid, grid)
    power = [{letter: np.abs(centred_fourier(wavelet, letter, d_xyz[a] * (U * view.u[a] + V * view.v[a]))) ** 2
              for letter in "ad"} for a in range(3)]
    integral = np.array([np.sum(power[0]["ad"[code & 1]] * power[1]["ad"[code >> 1 & 1]]
                                * power[2]["ad"[code >> 2 & 1]]) for code in range(8)])
    integral *= (grid[1] - grid[0]) ** 2 / (2.0 * np.pi) ** 2  # Parseval: the 2-D energy
    return np.outer(2.0 ** np.arange(MAX_LEVELS), integral).reshape(-1)


class SplatEstimate:
    """The error of each splatting frame against the final image, from the coefficients still to splat
    (docs/splatting.md §5).

    The rest's image is predicted as ``A + D``: ``A`` the approximation band's footprints drawn signed (Gaussians
    of the band's energy and variance ``order / 12`` per axis, times ``2^L`` voxels), ``D`` the detail bands' as
    an energy density ``V`` per channel (each footprint's energy, :func:`band_energies`, times the coefficient's
    value in that channel squared, spread as a Gaussian of :data:`DETAIL_WIDTH` ``2^m`` voxels).  The relative RMS
    is ``sqrt(mean(A^2 + V))`` and the relative maximum ``max(|A| + CREST sqrt(V))`` (a field of many oscillating
    footprints peaks near three of its local RMS), both over the largest magnitude of ``frame + A``, the final image
    as predicted; times margins (docs/splatting.md §5 has their measured rates).  A perspective view magnifies each
    coefficient by its depth.
    """

    RMS_MARGIN, MAX_MARGIN, CREST = 2.0, 1.7, 3.0

    def __init__(self, r, view):
        H, W = view.size
        self.view, self.channels = view, r.wv.channels
        self.cell = max(1, -(-max(H, W) // GRID))  # pixels per cell, per side
        self.rows, self.cols = -(-H // self.cell), -(-W // self.cell)
        d = spacing_xyz(r.wv.spacing)
        self.reach = np.array([np.linalg.norm(view.v * d), np.linalg.norm(view.u * d)])  # a voxel along rows, cols
        self.frame, self.done = r.wv.frame, 0
        self.groups, pixels, counted = [], 0.0, 0
        for g, group in zip(r.wv.groups, r.groups):
            table = group["table"]
            self.groups.append(dict(
                wavelet=g.wavelet, table=table, channels=list(g.channels), count=group["count"], levels=r.wv.levels,
                energy=band_energies(g.wavelet, r.wv.spacing, view) * float(np.prod(d)) ** 2,
                lattice=_lattices(g.wavelet)))
        for gr in self.groups:  # placed once per view (docs/splatting.md §5): 14 bytes a coefficient
            n = gr["count"]
            gr["row"], gr["col"], gr["px"] = (np.empty(n, np.float32) for _ in range(3))
            gr["band"] = np.empty(n, np.int16)
            for lo in range(0, n, CHUNK):
                hi = min(lo + CHUNK, n)
                gr["row"][lo:hi], gr["col"][lo:hi], gr["px"][lo:hi], gr["band"][lo:hi] = self._place(gr, lo, hi)
            pixels, counted = pixels + float(np.sum(gr["px"], dtype=np.float64)), counted + n
        # the mean world width of a pixel at the coefficients; the cells' margin holds every footprint reaching
        # into the image: 3 standard deviations of the widest
        self.scale = pixels / max(counted, 1) if view.perspective else view.pixel  # world units per pixel
        widest = max((max(self._sigmas(gr)[0].max(), self._sigmas(gr)[1][: gr["levels"] + 1].max())
                      for gr in self.groups), default=0.0)
        # zoomed in, the widest footprints span more than the image: cells k times larger keep the margin within
        # GRID cells (the maps' memory bounded; the finest detail's then still about 2 cells wide)
        k = max(1, int(np.ceil(3.0 * widest / GRID)))
        if k > 1:
            self.cell *= k
            self.rows, self.cols = -(-H // self.cell), -(-W // self.cell)
            for gr in self.groups:
                gr["row"], gr["col"] = ((gr[key] + np.float32(0.5)) / np.float32(k) - np.float32(0.5)
                                        for key in ("row", "col"))
            widest /= k
        self.pad = int(np.ceil(3.0 * widest)) + 2
        if view.perspective:  # at the cells' centres (the last cell's within the image, where it is cut short)
            rows, cols = (np.minimum(np.arange(n) * self.cell + self.cell // 2, side - 1)
                          for n, side in ((self.rows, H), (self.cols, W)))
            self.obliquity = view.obliquity()[np.ix_(rows, cols)][..., None]
        shape = (self.rows + 2 * self.pad, self.cols + 2 * self.pad)
        for gr in self.groups:
            gr["signed"] = np.zeros((len(gr["channels"]), 1) + shape)
            gr["detail"] = np.zeros((len(gr["channels"]), MAX_LEVELS) + shape)  # per channel: docs/splatting.md §5
            self._deposit(gr, 0, gr["count"], +1.0)

    def _sigmas(self, gr) -> tuple:
        """Standard deviations in cells (rows, cols): the approximation's, and each detail level's (MAX_LEVELS, 2)."""
        per_voxel = self.reach / (self.scale * self.cell)
        approx = np.sqrt(gr["wavelet"].order / 12.0) * 2.0 ** gr["levels"] * per_voxel
        return approx, DETAIL_WIDTH * np.outer(2.0 ** np.arange(MAX_LEVELS), per_voxel)

    def _place(self, gr, lo, hi) -> tuple:
        """Coefficients lo..hi of a group: their (row, col) in cells, band codes, and world units per pixel."""
        t = gr["table"]
        band = t.level[lo:hi].astype(np.int64) * 8 + t.key_code[lo:hi]
        offset, step, support = gr["lattice"]
        fine = offset[band] + step[band, None] * (t.index[lo:hi] + support[band] / 2.0)
        world = fine_to_world(fine, gr["wavelet"].order, *self.frame)
        cols_rows = self.view.to_pixels(world)
        if self.view.perspective:
            px = np.sqrt(self.view.slope[0] * self.view.slope[1]) * np.maximum(self.view.depth(world), 1e-12)
        else:
            px = np.full(hi - lo, self.view.pixel)
        return (cols_rows[:, 1] + 0.5) / self.cell - 0.5, (cols_rows[:, 0] + 0.5) / self.cell - 0.5, px, band

    def _deposit(self, gr, lo, hi, sign):
        """Add (sign +1) or take away (-1) coefficients lo..hi of a group to its maps, bilinear in the cells."""
        approx_sigma = self._sigmas(gr)[0]
        for start in range(lo, hi, CHUNK):
            end = min(start + CHUNK, hi)
            row, col = (gr[key][start:end].astype(np.float64) + self.pad for key in ("row", "col"))
            px, band = gr["px"][start:end].astype(np.float64), gr["band"][start:end].astype(np.int64)
            energy = gr["energy"][band] / px ** 2  # in pixels: each pixel's energy
            values = np.asarray(gr["table"].values[start:end], np.float64)
            approx = band % 8 == 0
            # the approximation: a Gaussian of the band's energy, integral^2 / (4 pi s_r s_c) in pixels
            amp = np.sqrt(energy[approx] * 4.0 * np.pi * np.prod(approx_sigma) * self.cell ** 2)
            detail = ~approx
            _bilinear(gr["signed"], 0, row[approx], col[approx], sign * values[approx] * amp[:, None])
            # each channel's own energy: their details differ
            _bilinear(gr["detail"], band[detail] // 8, row[detail], col[detail],
                      sign * energy[detail, None] * values[detail] ** 2)

    def add(self, image: np.ndarray, done: int) -> tuple:
        """(relative RMS, relative max) estimated for ``image`` after ``done`` coefficients of every group."""
        signed = np.zeros((self.rows, self.cols, self.channels))
        variance = np.zeros_like(signed)
        for gr in self.groups:
            self._deposit(gr, min(self.done, gr["count"]), min(done, gr["count"]), -1.0)
            approx_sigma, detail_sigma = self._sigmas(gr)
            inside = (slice(self.pad, self.pad + self.rows), slice(self.pad, self.pad + self.cols))
            for i, ch in enumerate(gr["channels"]):
                signed[..., ch] = _blur(gr["signed"][i], [approx_sigma])[inside]
                variance[..., ch] = np.maximum(_blur(gr["detail"][i], detail_sigma)[inside], 0.0)
        self.done = done
        signed /= self.cell ** 2  # per cell -> per pixel
        variance /= self.cell ** 2
        if self.view.perspective:  # the path length per unit depth of each pixel's ray, as the image
            signed, variance = signed * self.obliquity, variance * self.obliquity ** 2
        whole = np.repeat(np.repeat(signed, self.cell, 0), self.cell, 1)[: image.shape[0], : image.shape[1]]
        peak = max(float(np.max(np.abs(image + whole), initial=0.0)), np.finfo(np.float32).tiny)
        rms = np.sqrt(np.mean(signed ** 2 + variance))
        top = float(np.max(np.abs(signed) + self.CREST * np.sqrt(variance), initial=0.0))
        return self.RMS_MARGIN * float(rms) / peak, self.MAX_MARGIN * top / peak


def _lattices(wav) -> tuple:
    """:func:`band_lattice` of every band code ``level * 8 + code``: offsets and supports (8 MAX_LEVELS, 3), steps."""
    bands = [band_lattice(wav, "".join("ad"[code >> s & 1] for s in (2, 1, 0)), level)
             for level in range(MAX_LEVELS) for code in range(8)]
    return tuple(np.array([b[i] for b in bands]) for i in range(3))


def _bilinear(stacks, layer, row, col, weights):
    """Add weights (n, k) at fractional (row, col) of layers of k stacks of 2-D grids (k, layers, rows, cols), one
    column a stack, shared by the four nearest cells (off the grid: none)."""
    r0, c0 = np.floor(row).astype(np.int64), np.floor(col).astype(np.int64)
    fr, fc = row - r0, col - c0
    _, layers, rows, cols = stacks.shape
    r, c = np.concatenate([r0, r0, r0 + 1, r0 + 1]), np.concatenate([c0, c0 + 1, c0, c0 + 1])
    share = np.concatenate([(1 - fr) * (1 - fc), (1 - fr) * fc, fr * (1 - fc), fr * fc])
    ok = (r >= 0) & (r < rows) & (c >= 0) & (c < cols)
    flat = ((np.tile(np.broadcast_to(layer, r0.shape), 4) * rows + r) * cols + c)[ok]
    for stack, weight in zip(stacks, weights.T):
        stack += np.bincount(flat, (share * np.tile(weight, 4))[ok], minlength=stack.size).reshape(stack.shape)


def _blur(grids, sigmas) -> np.ndarray:
    """The sum of each grid blurred by its Gaussian (standard deviations in cells, rows and cols), in Fourier space."""
    total = None
    for grid, sigma in zip(grids, sigmas):
        if not grid.any():
            continue
        spectrum = fourier_gaussian(np.fft.rfft2(grid), tuple(sigma), n=grid.shape[1])
        total = spectrum if total is None else total + spectrum
    return np.zeros(grids[0].shape) if total is None else np.fft.irfft2(total, s=grids[0].shape)
