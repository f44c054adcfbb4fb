"""Splatting's error estimate (docs/splatting.md §5): the image of the coefficients still to splat, predicted
from the coefficients themselves, without the final image.

Splatting is linear, so the error of a frame is exactly the image of the coefficients not yet splatted.  The rest
is drawn signed on a grid of at most :data:`GRID` cells a side, each band's coefficients convolved in Fourier space
with its projected footprint (:func:`~clwave.splat.spectral.fft_texture`) as far as the cells resolve it; the part
of a detail band's energy beyond the cells' band limit (:func:`resolved_shares`), whose footprints oscillate about
zero within a cell, is drawn as an energy density, each footprint's energy (:func:`band_energies`) spread over its
width.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import fourier_gaussian

from ..model.geometry import band_lattice, fine_to_world, projected_halfwidths, spacing_xyz
from ..model.transform import band_code, band_key, band_level
from .spectral import centred_fourier, fft_texture
from .tables import MAX_LEVELS

SLICE_POINTS = 12  # per side of the slice grid integrating a band's footprint energy (docs/splatting.md §5), per
#                   lattice step of the widest support S (its spectral lobes are 2 pi / (S max(d)) wide; 64 points at
#                   least), times the spacings' largest ratio, up to 8 times

GRID = 64  # cells per side, at most, of the estimate's maps (an image larger than this: cells of several pixels;
#            docs/splatting.md §5 has the rates at 64 and 256)
CHUNK = 1 << 18  # coefficients placed at once
DETAIL_WIDTH = 0.5  # the standard deviation of a level-m detail footprint's square, in 2^m voxels along u or v
DIFFERENCE = 0.05  # the step of the footprints' differences in the log of magnification and in the slopes
SIGNED_SHARE = 0.25  # a detail band is drawn signed where the cells resolve at least this share of its energy (the
#                      rest of its energy as a density; below it, all of it: a band's signed map costs an FFT a frame)
LATTICE_CELLS = 2.0  # the signed maps' cells per lattice step of the approximation, at least (the image's cells split
FINE = 4             # up to FINE times a side where they are coarser; docs/splatting.md §5)


def _slice_power(wavelet, spacing, view) -> tuple:
    """The slice grid of world frequencies (n,) and ``prod_a |G_a(d_a (U u_a + V v_a))|^2`` on it for each key
    code at level 0 (8, n, n): :func:`band_energies` integrates it."""
    d_xyz = np.asarray(spacing, float)[::-1]
    reach = 16.0 * np.pi / float(np.min(d_xyz))  # |G|^2 is below 1e-6 of its peak beyond 16 pi / d
    points = max(64, SLICE_POINTS * max(wavelet.support("a"), wavelet.support("d")))
    grid = np.linspace(-reach, reach, int(points * min(8.0, np.ceil(np.max(d_xyz) / np.min(d_xyz)))))
    U, V = np.meshgrid(grid, grid)
    power = [{letter: np.abs(centred_fourier(wavelet, letter, d_xyz[a] * (U * view.u[a] + V * view.v[a]))) ** 2
              for letter in "ad"} for a in range(3)]
    return grid, np.array([np.prod([power[a][letter] for a, letter in enumerate(band_key(code)[::-1])], axis=0)
                           for code in range(8)])


def band_energies(wavelet, spacing, view) -> np.ndarray:
    """Image energy of a unit coefficient of each band id ``level * 8 + code`` (in world units at unit spacing;
    otherwise up to the factor ``(dx dy dz)^2``).

    Splatting is linear and a footprint is the projection of its function, so by the slice theorem a unit
    coefficient of band (m, key) draws the energy ``2^m I_key``, with ``I_key = ∫∫ prod_a |G_a(d_a (U u_a +
    V v_a))|^2 dU dV`` over the slice plane (G: :func:`~clwave.splat.spectral.centred_fourier`, d: the spacing);
    psi along the ray draws nothing.  A perspective view takes its axis (each coefficient's magnification is
    :class:`SplatEstimate`'s).
    """
    grid, power = _slice_power(wavelet, spacing, view)
    integral = power.sum(axis=(1, 2)) * (grid[1] - grid[0]) ** 2 / (2.0 * np.pi) ** 2  # Parseval: the 2-D energy
    return np.outer(2.0 ** np.arange(MAX_LEVELS), integral).reshape(-1)


def resolved_shares(wavelet, spacing, view, limit) -> np.ndarray:
    """The share of each band id's footprint energy at world frequencies ``|U|, |V| <= limit`` (a grid's band
    limit, pi over its cell's width): level m's footprint spectrum is level 0's at 2^m times the frequency."""
    grid, power = _slice_power(wavelet, spacing, view)
    total = power.sum(axis=(1, 2))
    shares = []
    for m in range(MAX_LEVELS):
        inside = np.abs(grid) <= 2.0 ** m * limit
        part = power[:, inside][:, :, inside].sum(axis=(1, 2))
        shares.append(np.divide(part, total, out=np.ones(8), where=total > 0))  # psi along the ray: nothing left
    return np.concatenate(shares)


class SplatEstimate:
    """The error of each splatting frame against the final image, from the coefficients still to splat
    (docs/splatting.md §5).

    The rest's image is predicted as ``S + D``: ``S`` drawn signed on the cells, each band's rest convolved with its
    projected footprint as far as the cells resolve it (the approximation always, a detail band where they resolve
    :data:`SIGNED_SHARE` of its energy), on cells split :attr:`fine` times a side where the approximation's lattice
    is finer than :data:`LATTICE_CELLS` cells; ``D`` the rest of the energy as a density ``V`` per channel (each
    footprint's energy, :func:`band_energies`, beyond the cells' band limit or whole, times the coefficient's value
    in that channel squared, spread as a Gaussian of :data:`DETAIL_WIDTH` ``2^m`` voxels).  The relative RMS is
    ``sqrt(mean(S^2 + V))`` and the relative maximum ``max(|S| + CREST sqrt(V))`` (a field of many oscillating
    footprints peaks near three of its local RMS), both at the cells, over the largest magnitude of ``frame + S``,
    the final image as predicted at the cells split :attr:`split` times (the frame's mean over each); times margins
    (docs/splatting.md §5 has their measured rates).  A perspective view magnifies each coefficient by its depth: its
    energy so, its signed footprint to first order in the log of that magnification and in its ray's slopes.
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
        # into the image: the widest's projected support (the coarsest level's phi)
        self.scale = pixels / max(counted, 1) if view.perspective else view.pixel  # world units per pixel
        widest = max((max(projected_halfwidths(gr["wavelet"], "aaa", gr["levels"], r.wv.spacing, view.u, view.v))
                      for gr in self.groups), default=0.0) / (self.scale * self.cell)
        # zoomed in, the widest footprints span more than the image: cells k times larger keep the margin within
        # GRID cells (the maps' memory bounded; the finest detail's then still about 2 cells wide)
        k = max(1, int(np.ceil(widest / GRID)))
        if k > 1:
            self.cell *= k
            self.rows, self.cols = -(-H // self.cell), -(-W // self.cell)
            for gr in self.groups:
                gr["row"], gr["col"] = ((gr[key] + np.float32(0.5)) / np.float32(k) - np.float32(0.5)
                                        for key in ("row", "col"))
            widest /= k
        self.pad = int(np.ceil(widest)) + 2
        if view.perspective:  # at the cells' centres (the last cell's within the image, where it is cut short)
            rows, cols = (np.minimum(np.arange(n) * self.cell + self.cell // 2, side - 1)
                          for n, side in ((self.rows, H), (self.cols, W)))
            self.obliquity = view.obliquity()[np.ix_(rows, cols)][..., None]
        shape = (self.rows + 2 * self.pad, self.cols + 2 * self.pad)
        # the signed maps on cells split `fine` times a side where the approximation's lattice step spans fewer than
        # LATTICE_CELLS cells: deposited bilinearly on coarser cells, its large coefficients of both signs, which
        # cancel in the image, aliased into the footprints' passband (docs/splatting.md §5); the final peak predicted
        # on the finest cells of whole pixels among them
        step = 2.0 ** r.wv.levels * float(np.min(self.reach)) / (self.scale * self.cell)
        self.fine = int(np.clip(np.ceil(LATTICE_CELLS / step), 1, FINE))
        self.split = max(p for p in range(1, self.fine + 1) if self.fine % p == 0 and self.cell % p == 0)
        for gr in self.groups:
            self._filters(gr, r.wv.spacing, shape)
            gr["signed"] = np.zeros((len(gr["channels"]), len(gr["kernels"]), shape[0] * self.fine,
                                     shape[1] * self.fine))
            gr["detail"] = np.zeros((len(gr["channels"]), MAX_LEVELS) + shape)  # per channel: docs/splatting.md §5
            self._deposit(gr, 0, gr["count"], +1.0)

    def _filters(self, gr, spacing, shape):
        """A group's signed bands (each band id's first layer, -1 where none) with their footprints' spectra on
        the cells, and the density's energy of each band with its Gaussians."""
        rows, cols = shape
        width = self.scale * self.cell  # world units per cell
        share = resolved_shares(gr["wavelet"], spacing, self.view, np.pi / width)
        present = np.unique(gr["band"])
        signed = [int(b) for b in present if band_code(b) == 0 or share[b] >= SIGNED_SHARE]
        gr["layer"] = np.full(8 * MAX_LEVELS, -1)
        gr["layer"][signed] = np.arange(len(signed)) * (4 if self.view.perspective else 1)
        # the density's energies: a signed band's beyond the cells' band limit, all of an unsigned one's
        gr["density"] = gr["energy"] * np.where(gr["layer"] >= 0, 1.0 - share, 1.0)
        kernels, d_xyz, h = [], spacing_xyz(spacing), DIFFERENCE
        fshape, fwidth = (rows * self.fine, cols * self.fine), width / self.fine
        for b in signed:
            base = _footprint(gr["wavelet"], b, d_xyz, self.view, fshape, fwidth)
            kernels.append(base)
            if self.view.perspective:  # its derivatives in the log of the magnification and in the ray's slopes
                kernels += [(_footprint(gr["wavelet"], b, d_xyz, self.view, fshape, fwidth * np.exp(h)) - base) / h,
                            (_footprint(gr["wavelet"], b, d_xyz, self.view, fshape, fwidth, (h, 0.0)) - base) / h,
                            (_footprint(gr["wavelet"], b, d_xyz, self.view, fshape, fwidth, (0.0, h)) - base) / h]
        gr["kernels"] = np.array(kernels).reshape(len(kernels), fshape[0], fshape[1] // 2 + 1)
        per_voxel = self.reach / width
        ones = np.ones((rows, cols // 2 + 1))
        gr["blurs"] = np.array([fourier_gaussian(ones, tuple(DETAIL_WIDTH * 2.0 ** m * per_voxel), n=cols)
                                for m in range(MAX_LEVELS)])

    def _place(self, gr, lo, hi) -> tuple:
        """Coefficients lo..hi of a group: their (row, col) in cells, band ids, and world units per pixel."""
        t = gr["table"]
        band = t.band[lo:hi].astype(np.int64)
        offset, step, support = gr["lattice"]
        fine = offset[band] + step[band, None] * (t.index[lo:hi] + support[band] / 2.0)
        world = fine_to_world(fine, gr["wavelet"].order, *self.frame)
        cols_rows = self.view.to_pixels(world)
        if self.view.perspective:
            px = np.sqrt(self.view.slope[0] * self.view.slope[1]) * np.maximum(self.view.depth(world), 1e-12)
        else:
            px = np.full(hi - lo, self.view.pixel)
        return (cols_rows[:, 1] + 0.5) / self.cell - 0.5, (cols_rows[:, 0] + 0.5) / self.cell - 0.5, px, band

    def _perspective(self, row, col, px) -> tuple:
        """The log of each coefficient's magnification over the mean, and its ray's slopes (s_u, s_v), from its
        place in cells and its pixel's world width (as View.to_pixels places it)."""
        (H, W), slope, principal = self.view.size, self.view.slope, self.view.principal
        su = ((col + 0.5) * self.cell - W / 2.0) * slope[0] + principal[0]
        sv = (H / 2.0 - (row + 0.5) * self.cell) * slope[1] + principal[1]
        return np.log(px / self.scale), su, sv

    def _deposit(self, gr, lo, hi, sign):
        """Add (sign +1) or take away (-1) coefficients lo..hi of a group to its maps, bilinear in the cells."""
        for start in range(lo, hi, CHUNK):
            end = min(start + CHUNK, hi)
            row, col = (gr[key][start:end].astype(np.float64) + self.pad for key in ("row", "col"))
            px, band = gr["px"][start:end].astype(np.float64), gr["band"][start:end].astype(np.int64)
            values = np.asarray(gr["table"].values[start:end], np.float64)
            layer = gr["layer"][band]
            signed = layer >= 0
            frow, fcol = ((row[signed] + 0.5) * self.fine - 0.5, (col[signed] + 0.5) * self.fine - 0.5)
            _bilinear(gr["signed"], layer[signed], frow, fcol, sign * values[signed])
            if self.view.perspective:  # each footprint magnified by its depth and sheared by its ray: to first order
                for i, term in enumerate(self._perspective(row[signed] - self.pad, col[signed] - self.pad,
                                                           px[signed])):
                    _bilinear(gr["signed"], layer[signed] + 1 + i, frow, fcol,
                              sign * values[signed] * term[:, None])
            energy = gr["density"][band] / px ** 2  # in pixels: each pixel's energy
            spread = energy > 0  # each channel's own energy: their details differ
            _bilinear(gr["detail"], band_level(band[spread]), row[spread], col[spread],
                      sign * energy[spread, None] * values[spread] ** 2)

    def add(self, image: np.ndarray, done: int) -> tuple:
        """(relative RMS, relative max) estimated for ``image`` after ``done`` coefficients of every group."""
        for gr in self.groups:
            self._deposit(gr, min(self.done, gr["count"]), min(done, gr["count"]), -1.0)
        self.done = done
        split, variance = self.split_maps()
        signed = _block_means(split, self.split)
        # the final image as predicted, at the cells (or the finest cells of whole pixels the signed maps resolve): at
        # the pixels, the frame's own fine overshoot, which the rest's unresolved details take back, stayed in its
        # peak; at coarse cells, a narrow peak is lost in its cell's mean (docs/splatting.md §5)
        means = self._cell_means(image, self.cell // self.split)
        peak = max(float(np.max(np.abs(means + split[:len(means), :means.shape[1]]), initial=0.0)),
                   np.finfo(np.float32).tiny)
        rms = np.sqrt(np.mean(signed ** 2 + variance))
        top = float(np.max(np.abs(signed) + self.CREST * np.sqrt(variance), initial=0.0))
        return self.RMS_MARGIN * float(rms) / peak, self.MAX_MARGIN * top / peak

    def _cell_means(self, image, cell) -> np.ndarray:
        """The image's mean over each cell of ``cell`` pixels a side (those of the last row and column cut short
        where the image ends)."""
        starts = [np.arange(0, side, cell) for side in image.shape[:2]]
        sums = np.add.reduceat(np.add.reduceat(image, starts[0], axis=0), starts[1], axis=1)
        counts = np.multiply.outer(*(np.diff(np.append(s, side)) for s, side in zip(starts, image.shape[:2])))
        return sums / counts[..., None]

    def maps(self) -> tuple:
        """The rest's image as drawn signed and its energy density, per pixel at each cell (rows, cols, channels)."""
        split, variance = self.split_maps()
        return _block_means(split, self.split), variance

    def split_maps(self) -> tuple:
        """The rest's image as drawn signed, at each cell split :attr:`split` times a side, and its energy density at
        each cell (rows, cols, channels)."""
        k, p = self.fine, self.split
        signed = np.zeros((self.rows * p, self.cols * p, self.channels))
        variance = np.zeros((self.rows, self.cols, self.channels))
        inside = (slice(self.pad, self.pad + self.rows), slice(self.pad, self.pad + self.cols))
        split = (slice(self.pad * p, (self.pad + self.rows) * p), slice(self.pad * p, (self.pad + self.cols) * p))
        for gr in self.groups:
            for i, ch in enumerate(gr["channels"]):
                signed[..., ch] = _block_means(_filtered(gr["signed"][i], gr["kernels"]), k // p)[split]
                variance[..., ch] = np.maximum(_filtered(gr["detail"][i], gr["blurs"])[inside], 0.0)
        variance /= self.cell ** 2  # per cell -> per pixel
        if self.view.perspective:  # the path length per unit depth of each pixel's ray, as the image
            signed = signed * np.repeat(np.repeat(self.obliquity, p, 0), p, 1)
            variance = variance * self.obliquity ** 2
        return signed, variance


def _block_means(grid, k) -> np.ndarray:
    """The means of a grid's k x k blocks (its sides multiples of k)."""
    if k == 1:
        return grid
    rows, cols = grid.shape[:2]
    return grid.reshape((rows // k, k, cols // k, k) + grid.shape[2:]).mean(axis=(1, 3))


def _lattices(wav) -> tuple:
    """:func:`band_lattice` of every band id ``level * 8 + code``: offsets and supports (8 MAX_LEVELS, 3), steps."""
    bands = [band_lattice(wav, band_key(b), band_level(b)) for b in range(8 * MAX_LEVELS)]
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


def _footprint(wavelet, band, d_xyz, view, shape, width, slopes=(0.0, 0.0)) -> np.ndarray:
    """The real FFT of band id ``band``'s footprint on a grid of ``shape`` cells of world width ``width``, along
    rays of ``slopes`` (s_u, s_v) (a cone beam's, :mod:`clwave.splat.perspective`), over the bilinear deposit's own
    transform (a tent of one cell each way)."""
    rows, cols = shape
    texture = fft_texture(wavelet, band_key(band), band_level(band), d_xyz, view.u + slopes[0] * view.n,
                          view.v + slopes[1] * view.n, cols, rows, cols * width, rows * width)
    tent = (np.sinc(np.fft.fftfreq(rows))[:, None] * np.sinc(np.fft.rfftfreq(cols))[None, :]) ** 2
    return np.fft.rfft2(np.roll(texture[::-1], 1, axis=0)) / tent  # rows run along -v


def _filtered(grids, filters) -> np.ndarray:
    """The sum of each grid filtered by its filter (the real FFT's half plane of the grid's size)."""
    total = None
    for grid, spectrum in zip(grids, filters):
        if not grid.any():
            continue
        part = np.fft.rfft2(grid) * spectrum
        total = part if total is None else total + part
    return np.zeros(grids.shape[1:]) if total is None else np.fft.irfft2(total, s=grids.shape[1:])
