"""One view's host tables for the splatting kernels (docs/splatting.md §2-3): the footprint
textures packed into one texel pool, where each band's coefficients land in pixels, and the
framebuffers (layers) the bands are drawn into."""

from __future__ import annotations

import math
import time

import numpy as np

from ..device.constants import CELL_SNAP, TILE
from ..errors import DeviceMemoryError
from ..model.geometry import fine_to_world, support_centres
from ..model.wavelet import WaveletVolume
from .textures import DEFAULT_OMEGA_MIN, FILTER_BELOW, cell_axes, footprints, plane_shape


KINKED_OMEGA_MIN = 56.0  # texel band for order <= 2 at every level (about pixel / 16 at 512^2 of 256^3)


POOL_GUARD = 16  # zeros around the texel pool: the CPU kernel reads whole 16-pixel rows


#: Haar textures with a cell axis are sampled CELL_REFINE times finer along their other axis (texels of
#: 1/(CELL_REFINE P) pixel; in a magnified view CELL_REFINE times the band's texels per pixel, rounded up from 2,
#: gathered below: texels_per_pixel): they are one column or row of samples (2 x N texels), so this is
#: cheap, and it takes the bilinear error at the kinks along that axis from 1e-3..3.4e-3 to <= 2.1e-4
#: of the line length (box of ones, pixel 1.0012 voxel, azimuth / elevation 0 / 10, 90 / 25, 30 / 0)
CELL_REFINE = 8


#: Cubic and quintic textures keep the bounding box of their samples above this fraction of their peak
#: (paper Fig. 9).  Near the edges of the projected support box, where only the support's corners
#: project, a cubic footprint is vanishingly small (its B-spline tails meet there to high order):
#: at 1e-4 a third of the pixel updates go (docs/splatting.md §1) while 64^3 at 128^2 (every
#: coefficient) stays 3.3e-4 of the image maximum from the exact line integrals, as untrimmed
#: (1e-3 would double that).  Haar and linear footprints fall linearly
#: to their box edges and are not trimmed.
TEXTURE_TOL = 1e-4


#: lookup bits of a texture (cl/splat/raster.h): u (v) samples interpolated linearly, u from P phase planes; both
#: clear: cells, nearest sample; GATHER_U: u samples of more than a pixel (a magnified view, s < 1: phase_rate),
#: interpolated linearly per pixel from one plane
LINEAR_U, LINEAR_V, GATHER_U = 1, 2, 4


class ViewTables:
    """Host-side tables of one channel group for one view: footprints, band placement and the
    framebuffers (layers) the bands are drawn into, every layer in one set of tables
    (``cl/splat/bin.cl``: the tiles of all layers are binned in one pass).

    ``layers`` is ``[(view, bands)]``, one per framebuffer: its resolved view (pixel and size;
    the direction is the image's) and the (level, key) bands drawn there, or None for every band
    not drawn in an earlier layer.  Bands drawn nowhere are culled (``band_tex = -1``).
    """

    #: the device tables, uploaded by name
    names = ("band_tex", "band_origin", "step_col", "step_row", "tex_box", "tex_layer", "layers", "tex_int",
             "tex_map", "texels")

    def __init__(self, wv: WaveletVolume, group: int, layers, omega_s=None, sampling="auto", device=None,
                 max_texels=None):
        g = wv.groups[group]
        wav = g.wavelet
        spacing = np.array(wv.spacing[::-1], float)  # (dx, dy, dz)
        image_view = layers[0][0]  # the image's view: the layers share its direction
        cells = cell_axes(wav, image_view.u, image_view.v)
        # Haar with u or v along a world axis: exact cells along that axis, where its voxels are a pixel wide or more
        # (narrower, the pixel filter needs samples: textures.FILTER_BELOW)
        if sampling == "auto" and any(cells) and min(
                spacing @ np.abs(w) for w, cell in zip((image_view.u, image_view.v), cells) if cell) \
                >= FILTER_BELOW * min(view.pixel for view, _ in layers):
            sampling = "cells"
        # one texture band for every layer, the image pixel's: a coarse layer's own (a coarser band) erred by
        # more than its upsampling (docs/splatting.md §4)
        self.omega_s = omega = omega_s if omega_s is not None else default_omega_s(image_view.pixel, min(wv.spacing),
                                                                                    wav.order)
        self.layer_of, self.texels_per_pixel, texel, phases, pixel = {}, {}, {}, {}, {}
        for li, (view, bands) in enumerate(layers):
            for b in g.bands:
                band = (b.level, b.key)
                if band in self.layer_of or (bands is not None and band not in bands):
                    continue
                # texels of exactly 1/P pixel, or of two pixels or more in a magnified view (cl/splat/raster.h)
                s = phase_rate(texels_per_pixel(wav.order, b.level, omega, view.pixel, min(wv.spacing),
                                                CELL_REFINE if sampling == "cells" else 1))
                self.layer_of[band] = li
                self.texels_per_pixel[band] = s
                texel[band] = view.pixel / s
                pixel[band] = view.pixel
                phases[band] = int(s) if s >= 1 and s == int(s) else 1  # the pool's phase planes (P below)
        start = time.perf_counter()
        self.textures = footprints(wav, wv.spacing, image_view.n, image_view.u, image_view.v, list(self.layer_of),
                                   omega_s=self.omega_s, sampling=sampling, tol=TEXTURE_TOL if wav.order >= 4 else 0.0,
                                   texel=texel, device=device, max_texels=max_texels, phases=phases,
                                   pixel=pixel)
        self.footprint_seconds = time.perf_counter() - start
        self.samplings = sorted({t.sampling for t in self.textures.values() if t is not None})

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
                m, bid, scale = band.level, band.id, 2.0 ** band.level
                # world centre of coefficient k = 0 (docs/model.md §4: X = o + 2^m (k + c0)), in (x, y, z)
                origins[bid] = fine_to_world(support_centres(wav, band.key, m, (0, 0, 0)), wav.order, wv.shape,
                                             wv.spacing, wv.origin)
                self.step_col[bid, :3] = scale * spacing * view.u / view.pixel
                self.step_row[bid, :3] = -scale * spacing * view.v / view.pixel
                tex = self.textures[(m, band.key)]
                if tex is None:  # psi along the view direction: its footprint vanishes
                    continue
                self.band_tex[bid] = len(ints)
                tex_layer.append((li, len(ints) - first_tex))
                # per axis: texels at 1/P pixel, bilinear (u from P phase planes), texels coarser than the
                # pixel (u gathered per pixel from one plane), or cells at s texels per pixel, nearest sample
                # (u gathered per pixel from one plane); cl/splat/raster.h
                s = self.texels_per_pixel[(m, band.key)]
                cell_u, cell_v = tex.cells
                whole = s >= 1 and s == int(s)  # a whole number of texels a pixel (phase_rate), by value
                P = 1 if cell_u else phases[(m, band.key)]
                su, sv = (view.pixel / h if cell else float(s) for h, cell in ((tex.h_u, cell_u), (tex.h_v, cell_v)))
                pool_texels = offset + math.prod(plane_shape(*tex.data.shape, P))
                if max_texels is not None and pool_texels > max_texels:
                    raise DeviceMemoryError(
                        f"the texel pool of this view needs more than {4 * max_texels / 2**20:,.0f} MiB: a pixel "
                        f"({view.pixel:.3g} world units) spans {round(s, 2):,g} texels; render a smaller extent or "
                        "more pixels")
                planes = pack_texture(tex.data, P)
                nv, nu = tex.data.shape
                boxes.append(_axis_box(nu, tex.centre_u, su, cell_u) + _axis_box(nv, tex.centre_v, sv, cell_v))
                lookup = (0 if cell_u else LINEAR_U if whole else GATHER_U) | (0 if cell_v else LINEAR_V)
                ints.append((offset, planes.shape[2], planes.shape[1], lookup))
                maps.append((tex.centre_u, tex.centre_v, su, sv))
                pool.append(planes.ravel())
                offset += planes.size
            if origins:
                self.band_origin[list(origins)] = view.to_pixels(np.array(list(origins.values())))
            self.layer_textures.append(len(ints) - first_tex)
        set_texture_tables(self, boxes, ints, maps, tex_layer, pool)


def set_texture_tables(tables, boxes, ints, maps, tex_layer, pool):
    """The per-texture device tables from their rows (``tex_box``, ``tex_int``, ``tex_map``, ``tex_layer``;
    one dummy row where a view draws nothing) and the texel pool with its guard of zeros after it (``pool``: its
    parts, or the whole pool, guards included, as one float32 array)."""
    tables.tex_box = np.array(boxes or [(0, -1, 0, -1)], np.float32).reshape(-1, 4)
    tables.tex_int = np.array(ints or [(0, 0, 0, 0)], np.int32).reshape(-1, 4)
    tables.tex_map = np.array(maps or [(0, 0, 0, 0)], np.float32).reshape(-1, 4)
    tables.tex_layer = np.array(tex_layer or [(0, 0)], np.int32).reshape(-1, 2)
    tables.texels = pool if isinstance(pool, np.ndarray) else np.concatenate(
        [np.asarray(x, np.float32) for x in pool] + [np.zeros(2 * POOL_GUARD, np.float32)])


def _axis_box(count, centre, steps, cell) -> tuple:
    """Pixel offsets from the splat centre of the first and last sample along one texture axis
    (``steps`` texels per pixel); a cell reaches half a texel beyond its centre, and ``CELL_SNAP`` pixels more,
    so that a pixel on its edge is visited by the splats on either side, whose lookup picks one (cl/splat/raster.h)."""
    if not cell:
        return -centre / steps, (count - 1 - centre) / steps
    return -(centre + 0.5) / steps - CELL_SNAP, (count - 0.5 - centre) / steps + CELL_SNAP


def pack_texture(data: np.ndarray, P: int) -> np.ndarray:
    """Phase planes of a texture sampled at 1/P pixel along u: (P, nv + 3, ceil(nu / P) + 2).

    Plane p, column q + 1 holds texel p + P q (``cl/splat/raster.h``), so a row of pixels
    reads contiguous memory.  Zero margins: a column either side, a row above and two below.
    """
    nv, nu = data.shape
    cols = plane_shape(nv, nu, P)[2]
    rows = np.zeros((nv + 3, cols * P), np.float32)
    rows[1:nv + 1, P:P + nu] = data  # texel iu at P + iu: column (iu // P) + 1 of plane iu % P
    return np.ascontiguousarray(rows.reshape(nv + 3, cols, P).transpose(2, 0, 1))


def texels_per_pixel(order: int, level: int, omega: float, pixel: float, d_min: float, refine: int = 1):
    """The texels per pixel of a band's texture (docs/splatting.md §2): at least the band ``omega`` of
    eq. 36 and the least band of the level's own prototype (:data:`DEFAULT_OMEGA_MIN`), times ``refine``
    (:data:`CELL_REFINE`); Haar and linear footprints have kinks (Haar: jumps), so bilinear resampling needs
    fine texels at every level.  An integer P >= 2 (texels of exactly 1/P pixel, phase planes) where the band
    asks for at least two texels a pixel; else, in a magnified view, the number below 2 that the band asks for
    (an orthographic view rounds it up from 1/2, :func:`phase_rate`; below, it is read by per-pixel interpolation,
    so that the texture does not grow with the magnification)."""
    least = DEFAULT_OMEGA_MIN[order] / 2.0 ** level if order >= 3 else KINKED_OMEGA_MIN
    s = max(omega, least) * pixel / (np.pi * d_min)
    if s >= 2.0:
        return int(np.ceil(s - 1e-9)) * refine
    s *= refine
    return int(np.ceil(s - 1e-9)) if s >= 2.0 else float(s)


#: A magnified view's textures are read from phase planes too, sampled at 1/P pixel with P = ceil(s) (1 or 2), where
#: the band asks for more than this many texels a pixel (s): their texels then stay within a factor 2 of the band's
#: per axis (within 4/3 of the finest a view at s >= 2 makes, pixel / 3), and a pixel update costs a fifth to a sixth
#: of the per-pixel gather's on PoCL (docs/splatting.md §2); deeper zooms gather, so their textures stop growing (the
#: CPU kernel gathers rates under 1 only)
PHASE_PLANES_FROM = 0.5


def phase_rate(s):
    """The texels per pixel a band's texture is sampled at in an orthographic view: ``s`` (:func:`texels_per_pixel`)
    rounded up to an integer, read from that many phase planes, from :data:`PHASE_PLANES_FROM`; below, ``s`` as it is
    (a number under 1), gathered per pixel."""
    return int(np.ceil(s - 1e-9)) if s > PHASE_PLANES_FROM else float(s)


#: Texture band factor per order: order-6 wavelets (condition 34.6, docs/model.md §2) cancel more, so the
#: texture error grows more in the image: full-set images of 24^3 hydrogen at 32^2, 3.4e-3 to 8.0e-3 of the
#: image maximum from the exact line integrals at the band 14, 5.1e-4 to 7.5e-4 at 28 (docs/splatting.md §1)
OMEGA_S_FACTOR = {6: 2.0}


#: The quarter-pixel rule of :func:`default_omega_s` holds down to pixels of this fraction of the finest voxel
#: spacing: a magnified view's finer pixels keep that texel (cubic 1/16 voxel, order 6 1/32; Haar and linear keep
#: pi/56 voxel, KINKED_OMEGA_MIN) and interpolate between texels, so its textures do not grow with the
#: magnification (docs/splatting.md §2)
FINEST_PIXEL = 0.25


def default_omega_s(pixel, min_spacing, order=4) -> float:
    """Texture band: the paper's 14, finer when pixels are small (texel <= pixel / 4, down to pixels of
    :data:`FINEST_PIXEL` voxel); twice that for order 6."""
    finest = max(pixel, FINEST_PIXEL * min_spacing)
    return max(14.0, 4.0 * np.pi * min_spacing / finest) * OMEGA_S_FACTOR.get(order, 1.0)


MAX_LEVELS = 8  # band id = level * 8 + subband code must fit the 64-entry table
