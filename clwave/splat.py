"""Wavelet splatting (paper §4): X-ray images as sums of basis-function footprints.

Every kept coefficient c of band (m, key) adds ``c * T_{m,key}(mu - mu_c, nu - nu_c)``
to the image (paper eq. 29, MATH.md §6), where T is the footprint texture of the
prototype (:mod:`clwave.footprint`, Fourier projection slicing) and (mu_c, nu_c) the
projection of the centre of the basis support.  On the device
(``cl/splat_bin.cl``, ``cl/splat_raster.cl``): project -> per-chunk counts per (tile,
texture) -> scan -> per-tile ranges -> placement of a record per (tile, splat) pair (a
deterministic counting sort by tile and texture) -> accumulate per tile.  The result is the
line integral ``∫ f(p - t n) dt`` of each channel in world units (CONVENTIONS.md "Outputs").
"""

from __future__ import annotations

import dataclasses
import time
from functools import lru_cache

import numpy as np
import scipy.ndimage
import scipy.sparse
import pyopencl as cl
import pyopencl.array as cla
from pyopencl.tools import ImmediateAllocator, MemoryPool
from pyopencl.reduction import ReductionKernel
from pyopencl.scan import ExclusiveScanKernel

from . import programs
from .camera import Camera
from .device import ComputeContext
from .errors import DeviceMemoryError, InputError
from .footprint import DEFAULT_OMEGA_MIN, cell_axes, footprints
from .result import RenderResult
from .wavelet import WaveletVolume

TILE = 16
MAX_LEVELS = 8  # band id = level * 8 + subband code must fit the 64-entry table
RECORD_BYTES = {1: 16, 2: 32, 3: 32, 4: 32}  # a (tile, splat) pair's record by channels (cl/splat_record.h)
TILE_LIST_SHARE = 0.25  # of the device's memory, at most, for the tile lists of one chunk of splats
#: binning work-items (chunks of consecutive splats) per compute unit: a GPU needs many; on a CPU
#: each chunk keeps a write position in every (tile, texture) run, and few keep those in cache
CHUNKS_PER_UNIT = dict(GPU=64, CPU=4)
KINKED_OMEGA_MIN = 56.0  # texel band for order <= 2 at every level (about pixel / 16 at 512^2 of 256^3)
POOL_GUARD = 16  # zeros around the texel pool: the CPU kernel reads whole 16-pixel rows
#: Haar textures with a cell axis are sampled CELL_REFINE times finer (texels of 1/(CELL_REFINE P)
#: pixel) along their other axis: they are one column or row of samples (2 x N texels), so this is
#: cheap, and it takes the bilinear error at the kinks along that axis from 1e-3..3.4e-3 to <= 2.1e-4
#: of the line length (box of ones, pixel 1.0012 voxel, azimuth / elevation 0 / 10, 90 / 25, 30 / 0)
CELL_REFINE = 8
#: Cubic textures keep the bounding box of their samples above this fraction of their peak
#: (paper Fig. 9).  Near the edges of the projected support box, where only the support's corners
#: project, a cubic footprint is vanishingly small (its B-spline tails meet there to high order):
#: at 1e-4, hydrogen 256^3 at 512^2 (5 %) has 32 % fewer pixel updates and renders 1.6x faster,
#: and 64^3 at 128^2 (every coefficient) stays 3.3e-4 of the image maximum from the exact line
#: integrals, as untrimmed (1e-3 would double that).  Haar and linear footprints fall linearly
#: to their box edges and are not trimmed.
TEXTURE_TOL = 1e-4
LINEAR_U, LINEAR_V = 1, 2  # lookup bits of a texture (cl/splat_raster.cl); clear: cells, nearest sample


class ViewTables:
    """Host-side tables of one channel group for one view: footprints, band placement and the
    framebuffers (layers) the bands are drawn into, every layer in one set of tables
    (``cl/splat_bin.cl``: the tiles of all layers are binned in one pass).

    ``layers`` is ``[(view, bands)]``, one per framebuffer: its resolved view (pixel and size;
    the direction is the frame's) and the (level, key) bands drawn there, or None for every band
    not drawn in an earlier layer.  Bands drawn nowhere are culled (``band_tex = -1``).
    """

    def __init__(self, wv: WaveletVolume, group: int, layers, omega_s=None, path="auto", device=None):
        g = wv.groups[group]
        wav = g.wavelet
        spacing = np.array(wv.spacing[::-1], float)  # (dx, dy, dz)
        shape = np.array(wv.shape[::-1], float)      # (nx, ny, nz)
        frame = layers[0][0]  # the image's view: the layers share its direction
        if path == "auto" and any(cell_axes(wav, frame.u, frame.v)):
            path = "cells"  # Haar with u or v along a world axis: exact cells along that axis
        # the texture band of each layer (a layer's pixel sets its default), the image's reported
        omegas = [omega_s if omega_s is not None else default_omega_s(view.pixel, min(wv.spacing))
                  for view, _ in layers]
        self.omega_s = omegas[0]
        self.layer_of, self.texels_per_pixel, texel = {}, {}, {}
        for li, ((view, bands), omega) in enumerate(zip(layers, omegas)):
            for b in g.bands:
                band = (b.level, b.key)
                if band in self.layer_of or (bands is not None and band not in bands):
                    continue
                # texels of exactly 1/P pixel (cl/splat_raster.cl), at least the band of eq. 36 and the
                # least band of the level's own prototype (clwave.footprint); Haar and linear footprints
                # have kinks (Haar: jumps), so bilinear resampling needs fine texels at every level
                least = DEFAULT_OMEGA_MIN[wav.order] / 2.0 ** b.level if wav.order >= 3 else KINKED_OMEGA_MIN
                P = max(2, int(np.ceil(max(omega, least) * view.pixel / (np.pi * min(wv.spacing)) - 1e-9)))
                self.layer_of[band] = li
                self.texels_per_pixel[band] = P * (CELL_REFINE if path == "cells" else 1)
                texel[band] = view.pixel / self.texels_per_pixel[band]
        start = time.perf_counter()
        self.textures = footprints(wav, wv.spacing, frame.n, frame.u, frame.v, list(self.layer_of),
                                   omega_s=self.omega_s, path=path, tol=TEXTURE_TOL if wav.order == 4 else 0.0,
                                   texel=texel, device=device)
        self.footprint_seconds = time.perf_counter() - start
        self.paths = sorted({t.path for t in self.textures.values() if t is not None})

        self.band_tex = np.full(8 * MAX_LEVELS, -1, np.int32)
        self.band_origin = np.zeros((8 * MAX_LEVELS, 2), np.float32)
        self.step_col = np.zeros((8 * MAX_LEVELS, 4), np.float32)
        self.step_row = np.zeros((8 * MAX_LEVELS, 4), np.float32)
        self.layers = np.zeros((len(layers), 4), np.int32)  # (width, height, first tile, first pixel)
        boxes, ints, maps, tex_layer, pool, offset = [], [], [], [], [np.zeros(POOL_GUARD)], POOL_GUARD
        self.tiles = self.pixels = 0
        self.layer_textures = []  # textures drawn in each layer
        for li, (view, _) in enumerate(layers):
            H, W = view.size
            self.layers[li] = (W, H, self.tiles, self.pixels)
            self.tiles += -(-W // TILE) * -(-H // TILE)
            self.pixels += H * W
            origins, first_tex = {}, len(ints)
            for band in g.bands:
                if self.layer_of.get((band.level, band.key)) != li:
                    continue
                m, key_xyz, bid, scale = band.level, band.key[::-1], band.level * 8 + band.code, 2.0 ** band.level
                # world centre of coefficient k = 0 (MATH.md §6: X = o + 2^m (k + c0)), in (x, y, z)
                fine = np.array([wav.offset(letter, m) + scale * wav.support(letter) / 2.0 for letter in key_xyz])
                origins[bid] = np.asarray(wv.origin) + (fine - wav.order / 2.0 - (shape - 1) / 2.0) * spacing
                self.step_col[bid, :3] = scale * spacing * view.u / view.pixel
                self.step_row[bid, :3] = -scale * spacing * view.v / view.pixel
                tex = self.textures[(m, band.key)]
                if tex is None:  # psi along the view direction: its footprint vanishes
                    continue
                self.band_tex[bid] = len(ints)
                tex_layer.append((li, len(ints) - first_tex))
                # per axis: texels at 1/P pixel, bilinear (u from P phase planes), or cells at s texels
                # per pixel, nearest sample (u gathered per pixel from one plane); cl/splat_raster.cl
                P = self.texels_per_pixel[(m, band.key)]
                cell_u, cell_v = tex.cells
                su, sv = (view.pixel / h if cell else float(P) for h, cell in ((tex.h_u, cell_u), (tex.h_v, cell_v)))
                planes = pack_texture(tex.data, 1 if cell_u else P)
                nv, nu = tex.data.shape
                boxes.append(_axis_box(nu, tex.centre_u, su, cell_u) + _axis_box(nv, tex.centre_v, sv, cell_v))
                lookup = (0 if cell_u else LINEAR_U) | (0 if cell_v else LINEAR_V)
                ints.append((offset, planes.shape[2], planes.shape[1], lookup))
                maps.append((tex.centre_u, tex.centre_v, su, sv))
                pool.append(planes.ravel())
                offset += planes.size
            if origins:
                self.band_origin[list(origins)] = view.to_pixels(np.array(list(origins.values())))
            self.layer_textures.append(len(ints) - first_tex)
        self.tex_box = np.array(boxes or [(0, -1, 0, -1)], np.float32).reshape(-1, 4)
        self.tex_int = np.array(ints or [(0, 0, 0, 0)], np.int32).reshape(-1, 4)
        self.tex_map = np.array(maps or [(0, 0, 0, 0)], np.float32).reshape(-1, 4)
        self.tex_layer = np.array(tex_layer or [(0, 0)], np.int32).reshape(-1, 2)
        self.texels = np.concatenate(pool + [np.zeros(2 * POOL_GUARD)]).astype(np.float32)


def _axis_box(count, centre, steps, cell) -> tuple:
    """Pixel offsets from the splat centre of the first and last sample along one texture axis
    (``steps`` texels per pixel); a cell reaches half a texel beyond its centre."""
    reach = 0.5 if cell else 0.0
    return -(centre + reach) / steps, (count - 1 + reach - centre) / steps


def pack_texture(data: np.ndarray, P: int) -> np.ndarray:
    """Phase planes of a texture sampled at 1/P pixel along u: (P, nv + 3, ceil(nu / P) + 2).

    Plane p, column q + 1 holds texel p + P q (``cl/splat_raster.cl``), so a row of pixels
    reads contiguous memory.  Zero margins: a column either side, a row above and two below.
    """
    nv, nu = data.shape
    cols = -(-nu // P) + 2
    rows = np.zeros((nv + 3, cols * P), np.float32)
    rows[1:nv + 1, P:P + nu] = data  # texel iu at P + iu: column (iu // P) + 1 of plane iu % P
    return np.ascontiguousarray(rows.reshape(nv + 3, cols, P).transpose(2, 0, 1))


def bin_chunks(n: int, runs: int, info) -> int:
    """Number of chunks of consecutive splats the binning works in (one work-item each).

    Enough for every compute unit of the device (``info``: :class:`clwave.device.DeviceInfo`),
    bounded by the splats and by the (tile, texture, chunk) count tables (``runs`` = tiles x
    textures): three of them, uint32, in at most 1/32 of the device's memory.
    """
    per_unit = CHUNKS_PER_UNIT["GPU" if info.kind == "GPU" else "CPU"]
    entries = min(info.max_alloc // 4, info.global_mem // 32 // 12)
    return max(1, min(n, per_unit * info.compute_units, entries // runs))


def default_omega_s(pixel, min_spacing) -> float:
    """Texture band: the paper's 14, finer when pixels are small (texel <= pixel / 4)."""
    return max(14.0, 4.0 * np.pi * min_spacing / pixel)


class SplatRenderer:
    """Uploads a wavelet volume's ranked coefficients once and splats any view.

    Parameters
    ----------
    wv : WaveletVolume
    device : str or ComputeContext
    omega_s : float, optional
        Footprint band (paper eq. 35/36); default from the pixel size.
    path : "auto", "fft", "spatial" or "cells"
        How footprint textures are made (:func:`clwave.footprint.footprints`); "auto" takes
        "cells" for Haar when u or v is a world axis: along that axis (or both) the footprint
        is its 2 exact cells, looked up by nearest sample, and along the other it is sampled
        at 1/(8 P) pixel (:data:`CELL_REFINE`).  ``meta["texture_path"]`` says what ran:
        "fft", "spatial", "cells" (both axes), "cells-u" or "cells-v" (that axis only).
    coarse : float, optional
        Tolerance, relative to the image maximum, for drawing coarse cubic bands into
        coarser framebuffers that are upsampled with the cubic B-spline (issue §2; see
        :func:`coarse_factor`).  None (default): every band at the image's pixel.
    """

    def __init__(self, wv: WaveletVolume, device=None, omega_s=None, path="auto", coarse=None):
        if not isinstance(wv, WaveletVolume):
            raise InputError("splatting needs a clwave.WaveletVolume (WaveletVolume.from_volume(...))")
        if wv.levels >= MAX_LEVELS:
            raise InputError(f"splatting supports up to {MAX_LEVELS - 1} levels, the volume has {wv.levels}")
        if coarse is not None and not (isinstance(coarse, (int, float)) and 0 < coarse < 1):
            raise InputError(f"coarse={coarse!r} must be a tolerance between 0 and 1 (e.g. 1e-2), or None")
        self.wv, self.omega_s, self.path, self.coarse = wv, omega_s, path, coarse
        self.cc = ComputeContext.get(device)
        start = time.perf_counter()
        px = 1 if self.cc.info.kind == "GPU" else TILE * TILE
        # one build per channel count of the groups: a scalar volume accumulates one channel
        self.kernels = {c: programs.build(self.cc, ["splat_bin.cl", "splat_raster.cl"],
                                          {"CLW_PX": px, "CLW_CHANNELS": c})
                        for c in sorted({len(g.channels) for g in wv.groups})}
        self.local_size = TILE * TILE // px
        # binning chunks: on a CPU one work-item per group, so the few chunks spread over the cores
        self.bin_local = None if self.cc.info.kind == "GPU" else (1,)
        ctx = self.cc.ctx
        self.scan = ExclusiveScanKernel(ctx, np.uint32, "a+b", neutral="0")
        self.pixel_updates = ReductionKernel(
            ctx, np.int64, neutral="0", reduce_expr="a+b", arguments="__global const int4 *bbox",
            map_expr="bbox[i].z < bbox[i].x ? 0 : (long)(bbox[i].z - bbox[i].x + 1) * (bbox[i].w - bbox[i].y + 1)")
        self.compile_seconds = time.perf_counter() - start
        self.groups = []
        q = self.cc.queue
        # per-chunk scratch comes from a pool that keeps its buffers, and the tile lists from one
        # buffer grown as needed, so a new view does not map (and the OS zero) fresh pages: a
        # gigabyte of records takes a third of a second to map
        self.scratch = MemoryPool(ImmediateAllocator(q))
        self._tile_lists = None
        for gi, g in enumerate(wv.groups):
            table = wv.ranked(gi)
            coef = np.zeros((len(table.level), 4), np.int32)
            coef[:, :3] = table.index[:, ::-1]  # (k_x, k_y, k_z)
            coef[:, 3] = table.level.astype(np.int32) * 8 + table.key_code  # bit 0: psi along x
            values = np.zeros((len(table.level), 4), np.float32)
            values[:, : table.values.shape[1]] = table.values
            # bands without a kept coefficient get no texture (at 1 % kept, 8 of hydrogen's 22)
            kept = set(np.unique(coef[:, 3]).tolist())
            present = {(b.level, b.key) for b in g.bands if b.level * 8 + b.code in kept}
            self.groups.append(dict(coef=cla.to_device(q, coef), values=cla.to_device(q, values),
                                    count=len(coef), channels=len(g.channels), present=present,
                                    energy=_energy_prefix(table.values)))

    def tile_lists(self, nbytes: int):
        """A device buffer of at least ``nbytes`` for the tile lists, kept between chunks and views."""
        if self._tile_lists is None or self._tile_lists.size < nbytes:
            self._tile_lists = None  # released before the larger one is made
            room = max(nbytes, min(nbytes + nbytes // 4, self.cc.info.max_alloc))  # room to grow
            self._tile_lists = cl.Buffer(self.cc.ctx, cl.mem_flags.READ_WRITE, room)
        return self._tile_lists

    @property
    def count(self) -> int:
        return self.groups[0]["count"] if self.groups else 0

    # -------------------------------------------------------------- drawing
    def begin(self, camera: Camera):
        """Start a frame: resolve the view, make footprints, zero the framebuffers."""
        if not isinstance(camera, Camera):
            raise InputError("camera must be a clwave.Camera")
        view = camera.view(self.wv)
        # framebuffer factor of each band that has coefficients, per group: 1 unless drawn coarse
        factors = [{(b.level, b.key): coarse_factor(g.wavelet.order, b.level, self.wv.levels, b.key == "aaa",
                                                      view.pixel, min(self.wv.spacing), self.coarse)
                    if self.coarse else 1 for b in g.bands if (b.level, b.key) in gr["present"]}
                   for g, gr in zip(self.wv.groups, self.groups)]
        layers = [Layer(view, F) for F in sorted({f for fg in factors for f in fg.values()} | {1})]
        fb_bytes = sum(layer.view.size[0] * layer.view.size[1] for layer in layers) * 16
        if fb_bytes > self.cc.info.max_alloc:
            H, W = view.size
            raise DeviceMemoryError(
                f"a {H}x{W} image needs {fb_bytes / 2**20:.0f} MiB of framebuffers but {self.cc.info.name} "
                f"allows {self.cc.info.max_alloc / 2**20:.0f} MiB per buffer; render a smaller image")
        tables = [ViewTables(self.wv, gi, [(layer.view, {band for band, f in fg.items() if f == layer.factor})
                                           for layer in layers], self.omega_s, self.path, device=self.cc)
                  for gi, fg in enumerate(factors)]
        return Frame(self, view, layers, tables)


#: Coarse framebuffers (issue §2): worst error, relative to the image maximum, of one band kind
#: drawn at coarse pixels of ``ratio * 2^m d_min`` (level m) and upsampled with the prefiltered
#: cubic B-spline, over three views of random 32^3, Shepp-Logan 64^3 and hydrogen 64^3 volumes
#: (cubic, 3 levels, all coefficients, pixel 0.866 voxel): the approximation band 9.9e-3 at
#: ratio 0.433 (8.7e-4 at 0.217); level-3 wavelets 5.0e-3 at 0.217 (0.16 at 0.433); level-2
#: wavelets 5.2e-2 at 0.433.  The error grows like ratio^4 (x11-32 per doubling).
COARSE_REFERENCE = dict(approximation=(np.sqrt(3) / 4, 1.0e-2), wavelet=(np.sqrt(3) / 8, 5.0e-3))
COARSE_MARGIN = 8  # coarse pixels around the image: the prefilter's mirror ends decay by 0.268^8


def coarse_factor(order: int, level: int, levels: int, approximation: bool, pixel: float, d_min: float,
                  tolerance: float) -> int:
    """Framebuffer coarsening (a power of 2) of one band for a tolerance.

    The tolerance is shared out: half to the approximation band, a quarter to the coarsest
    wavelet level, an eighth to the next, and so on, so the errors sum to less than it.  A
    band's share e allows coarse pixels up to ``ratio (e / e_ref)^(1/4) 2^m d_min`` from
    :data:`COARSE_REFERENCE` (cubic B-spline interpolation errs like the fourth power of
    the spacing).  Only cubic bands are coarsened (the others have kinks).

    >>> pixel = 3 ** 0.5 / 2  # 256^3 at 512^2 (the default extent)
    >>> [coarse_factor(4, 3, 3, a, pixel, 1.0, 2e-2) for a in (True, False)]
    [4, 2]
    >>> [coarse_factor(4, 3, 3, a, pixel, 1.0, 1e-2) for a in (True, False)]
    [2, 1]
    >>> coarse_factor(2, 3, 3, True, pixel, 1.0, 1e-2)
    1
    """
    if order != 4:
        return 1
    ratio, error = COARSE_REFERENCE["approximation" if approximation else "wavelet"]
    share = tolerance / 2.0 if approximation else tolerance / 2.0 ** (levels - level + 2)
    limit = ratio * (share / error) ** 0.25 * 2.0 ** level * d_min
    factor = 1
    while 2 * factor * pixel <= limit * (1 + 1e-9):
        factor *= 2
    return factor


def _bspline3(t) -> np.ndarray:
    """The centred cubic B-spline."""
    t = np.abs(t)
    return np.where(t < 1, 2 / 3 - t * t + t ** 3 / 2, np.where(t < 2, (2 - t) ** 3 / 6, 0.0))


class Layer:
    """One framebuffer's view: the image's pixel times ``factor`` (coarse bands are drawn there)."""

    def __init__(self, view, factor: int):
        H, W = view.size
        if factor > 1:  # same centre, pixel x factor, a margin around the image
            size = (-(-H // factor) + 2 * COARSE_MARGIN, -(-W // factor) + 2 * COARSE_MARGIN)
            view = dataclasses.replace(view, size=size, pixel=view.pixel * factor)
        self.view, self.fine, self.factor = view, (H, W), factor

    def image(self, pixels: np.ndarray) -> np.ndarray:
        """This framebuffer's (h * w, C) pixels at the image's pixels, (H, W, C) float32."""
        img = pixels.reshape(self.view.size + pixels.shape[1:])
        if self.factor == 1:
            return img
        return np.stack([upsample(img[..., c], self.fine, self.factor) for c in range(img.shape[2])], axis=-1)


def upsample(samples: np.ndarray, shape: tuple, factor: int) -> np.ndarray:
    """(h, w) samples at coarse pixels -> their prefiltered cubic B-spline interpolant at the
    fine pixel centres of ``shape`` (same centre, ``factor`` fine pixels per coarse one), float32.

    The B-spline coefficients come from ``scipy.ndimage.spline_filter`` (mirrored ends); each
    fine pixel then sums the 4 x 4 coefficients under it, one axis at a time, as sparse products.
    (Dense matrix products did the same through BLAS, whose idle threads then spun on the cores
    the next view's kernels needed.)
    """
    coeffs = scipy.ndimage.spline_filter(samples, order=3, mode="mirror", output=np.float32)
    rows = _taps(shape[0], samples.shape[0], factor) @ coeffs  # (H, w)
    return rows @ _taps(shape[1], samples.shape[1], factor).T  # (H, W); 3x faster than taps @ rows.T


@lru_cache(maxsize=16)
def _taps(n: int, coarse: int, factor: int) -> scipy.sparse.csr_matrix:
    """(n, coarse) float32 sparse matrix: the cubic B-spline weights of the 4 coarse coefficients
    under each of n fine pixel centres; fine pixel c lies at coarse index
    ``(c + 1/2 - n/2) / factor + coarse/2 - 1/2`` (taps off the coarse grid are dropped)."""
    at = (np.arange(n) + 0.5 - n / 2) / factor + coarse / 2 - 0.5
    index = np.floor(at).astype(np.intp)[:, None] + np.arange(-1, 3)
    weights = _bspline3(at[:, None] - index) * ((index >= 0) & (index < coarse))
    return scipy.sparse.csr_matrix((weights.astype(np.float32).ravel(), np.clip(index, 0, coarse - 1).ravel(),
                                    np.arange(0, 4 * n + 1, 4)), shape=(n, coarse))


class Frame:
    """One image being accumulated: splat coefficient ranges in importance order into the
    framebuffers (layers) of each channel group, all layers in one pass."""

    def __init__(self, renderer: SplatRenderer, view, layers: list, tables: list):
        self.r, self.view, self.layers, self.tables = renderer, view, layers, tables
        cc = renderer.cc
        self.device_tables = [{name: cc.upload(getattr(t, name)) for name in
                               ("band_tex", "band_origin", "step_col", "step_row", "tex_box", "tex_layer",
                                "layers", "tex_int", "tex_map", "texels")} for t in tables]
        self.fbs = [cla.zeros(cc.queue, (t.pixels * 4,), np.float32) for t in tables]
        self.stats = dict(splats=0, pairs=0, pixel_updates=0, bin_seconds=0.0, accumulate_seconds=0.0,
                          upsample_seconds=0.0)

    @property
    def footprint_seconds(self) -> float:
        return sum(t.footprint_seconds for t in self.tables)

    def splat(self, first: int, count: int):
        """Add coefficients ``first .. first + count`` (importance order) of every group."""
        for gi in range(len(self.r.groups)):
            n = max(0, min(count, self.r.groups[gi]["count"] - first))
            if n:
                self._splat_group(gi, first, n)
                self.stats["splats"] += n

    def _splat_group(self, gi, first, n):
        r, q = self.r, self.r.cc.queue
        g, t, tables = r.groups[gi], self.device_tables[gi], self.tables[gi]
        k = r.kernels[g["channels"]]
        start = time.perf_counter()
        centre = cla.empty(q, (n, 2), np.float32, allocator=r.scratch)
        bbox = cla.empty(q, (n, 4), np.int32, allocator=r.scratch)
        stex = cla.empty(q, (n,), np.int32, allocator=r.scratch)
        counts = cla.empty(q, (n,), np.uint32, allocator=r.scratch)
        k.splat_project(q, (n,), None, np.uint32(n), np.uint32(first), g["coef"].data, t["band_tex"],
                        t["band_origin"], t["step_col"], t["step_row"], t["tex_box"], t["tex_layer"], t["layers"],
                        centre.data, bbox.data, stex.data, counts.data)
        total = int(cla.sum(counts, dtype=np.uint64).get())
        pair_bytes = RECORD_BYTES[g["channels"]]
        # pairs: uint32 offsets, and record indices (pairs x 2 uint4s) that stay within 32 bits
        budget = min(int(min(r.cc.info.max_alloc, r.cc.info.global_mem * TILE_LIST_SHARE)) // pair_bytes,
                     2**31 - 1)
        if total > budget and n > 1:  # too many tile pairs for the device: split the chunk
            half = n // 2
            self.stats["bin_seconds"] += time.perf_counter() - start
            self._splat_group(gi, first, half)
            self._splat_group(gi, first + half, n - half)
            return
        if total > budget:
            raise DeviceMemoryError(f"one splat needs {total * pair_bytes} bytes of tile lists, more "
                                    f"than {r.cc.info.name} can hold; render a smaller image")
        tiles = tables.tiles
        ranges = cla.zeros(q, (tiles, 2), np.uint32, allocator=r.scratch)
        records = r.tile_lists(max(total, 1) * pair_bytes)
        if total:
            textures = max(tables.layer_textures)
            chunks = bin_chunks(n, tiles * textures, r.cc.info)
            chunk = -(-n // chunks)
            # chunk-major counts (each chunk's together, cached by its core), scanned run-major,
            # then back to chunk-major as each chunk's write cursors
            table = cla.empty(q, (chunks * tiles * textures,), np.uint32, allocator=r.scratch)
            by_run, starts = cla.empty_like(table), cla.empty_like(table)
            sizes = (np.uint32(n), np.uint32(chunk), np.uint32(chunks), np.uint32(tiles), np.uint32(textures))
            inputs = (np.uint32(first), bbox.data, centre.data, stex.data, g["values"].data, t["tex_layer"],
                      t["layers"])
            runs = np.uint32(tiles * textures)
            k.splat_chunk_tiles(q, (chunks,), r.bin_local, *sizes, np.int32(0), *inputs, table.data, records)
            k.transpose_counts(q, (table.size,), None, np.uint32(chunks), runs, table.data, by_run.data)
            r.scan(by_run, starts)
            k.tile_ranges(q, (tiles,), None, np.uint32(tiles), np.uint32(textures), np.uint32(chunks),
                          np.uint32(total), starts.data, ranges.data)
            k.transpose_counts(q, (table.size,), None, runs, np.uint32(chunks), starts.data, table.data)
            k.splat_chunk_tiles(q, (chunks,), r.bin_local, *sizes, np.int32(1), *inputs, table.data, records)
        q.finish()
        mid = time.perf_counter()
        k.splat_accumulate(q, (tiles * r.local_size,), (r.local_size,), np.int32(len(tables.layers)), t["layers"],
                           ranges.data, records, t["tex_int"], t["tex_map"], t["texels"], self.fbs[gi].data)
        q.finish()
        self.stats["bin_seconds"] += mid - start
        self.stats["accumulate_seconds"] += time.perf_counter() - mid
        self.stats["pairs"] += total
        self.stats["pixel_updates"] += int(r.pixel_updates(bbox, range=slice(0, n), queue=q).get())

    def image(self) -> np.ndarray:
        """The image so far as (H, W, C) float32: the framebuffers summed at the image's pixels."""
        H, W = self.view.size
        start = time.perf_counter()
        out = np.zeros((H, W, self.r.wv.channels), np.float32)
        for gi, g in enumerate(self.r.wv.groups):
            fb = self.fbs[gi].get().reshape(-1, 4)[:, : len(g.channels)]
            out[..., list(g.channels)] = sum(layer.image(fb[first: first + w * h]) for layer, (w, h, _, first), drawn
                                             in zip(self.layers, self.tables[gi].layers, self.tables[gi].layer_textures)
                                             if drawn)  # a layer may draw nothing of this group
        if len(self.layers) > 1:
            self.stats["upsample_seconds"] += time.perf_counter() - start
        return out


def splat(wv: WaveletVolume, camera: Camera, device=None, *, omega_s=None, path="auto", coarse=None,
          renderer: SplatRenderer | None = None) -> RenderResult:
    """X-ray image of a wavelet volume by wavelet splatting.

    Returns a :class:`RenderResult` whose ``image`` (H, W, C) holds the line integral of
    each channel in world units and whose ``meta`` reports the coefficients splatted,
    footprint, binning, accumulation and upsampling times (kernel compile time apart), the
    footprint texture path and the framebuffer factors.  ``omega_s``, ``path`` and
    ``coarse`` are those of :class:`SplatRenderer`.
    """
    r = renderer or SplatRenderer(wv, device=device, omega_s=omega_s, path=path, coarse=coarse)
    start = time.perf_counter()
    frame = r.begin(camera)
    frame.splat(0, r.count)
    image = frame.image()
    return RenderResult(image, _meta(r, frame, time.perf_counter() - start))


def _meta(r: SplatRenderer, frame: Frame, seconds: float) -> dict:
    tables = frame.tables
    return dict(method="splat", device=r.cc.describe(), coefficients=frame.stats["splats"],
                coefficients_total=r.count, tile_pairs=frame.stats["pairs"],
                pixel_updates=frame.stats["pixel_updates"],
                texture_path=sorted({p for t in tables for p in t.paths}),
                omega_s=tables[0].omega_s if tables else None,
                coarse=r.coarse, framebuffers=[layer.factor for layer in frame.layers],
                seconds=dict(total=seconds, footprints=frame.footprint_seconds,
                             binning=frame.stats["bin_seconds"], accumulation=frame.stats["accumulate_seconds"],
                             upsampling=frame.stats["upsample_seconds"], compile=r.compile_seconds))


def _energy_prefix(values) -> np.ndarray:
    """Cumulative coefficient energy sum c^2 over channels, in importance order."""
    return np.cumsum(np.sum(np.asarray(values, np.float64) ** 2, axis=1))
