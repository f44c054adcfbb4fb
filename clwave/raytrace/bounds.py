"""Bounds on |field| per block of fine cells, for empty-space skipping and early termination
(docs/raytracing.md §4): which blocks the kept supports reach, sums of coefficient bounds over
them, and their maxima per superblock."""

from __future__ import annotations

import numpy as np

from ..device.constants import BLOCK, SUPER
from ..model.geometry import band_lattice
from ..errors import ClwaveWarning, warn_outside
from ..model.wavelet import WaveletVolume


def superblocks(bound: np.ndarray, origin) -> tuple[np.ndarray, np.ndarray]:
    """The largest block bound per superblock of SUPER^3 blocks, and the superblocks' origin.

    ``bound`` (Z, Y, X) per block from block ``origin`` (z, y, x); superblock k holds blocks
    SUPER (origin_s + k) .. SUPER (origin_s + k + 1) - 1, so it is SUPER^3 BLOCK^3 aligned cells.
    """
    origin = np.asarray(origin, np.int64)
    s_origin = np.floor_divide(origin, SUPER)
    lead = origin - s_origin * SUPER
    count = -(-(np.array(bound.shape) + lead) // SUPER)
    padded = np.zeros(count * SUPER, np.float32)
    padded[tuple(slice(a, a + n) for a, n in zip(lead, bound.shape))] = bound
    return padded.reshape(count[0], SUPER, count[1], SUPER, count[2], SUPER).max(axis=(1, 3, 5)), s_origin


def block_sums(wv: WaveletVolume, weights):
    """Per block of BLOCK^3 fine cells, the sum of ``weights`` over the coefficients whose supports meet it.

    ``weights``: one (nz, ny, nx) array >= 0 per band, the groups' bands in order.  Returns
    ``(sums, origin, box)``: ``sums`` (Z, Y, X) over blocks ``origin + index`` (z, y, x), and the
    clip box ``(lo, hi)`` (x, y, z) in grid-0 fine coordinates around the blocks with a non-zero
    sum.  Per band and axis, block b is met by the coefficients k whose support
    ``[o + 2^m k, o + 2^m (k + S))`` meets ``[b B, (b + 1) B)``: a contiguous range of k, so the
    sum is separable (prefix sums along each axis in turn).
    """
    j0 = wv.groups[0].wavelet.order
    bands = []
    layout = [(g.wavelet, band) for g in wv.groups for band in g.bands]
    for (wav, band), weight in zip(layout, weights):
        if np.any(weight):
            off, step, sup = band_lattice(wav, band.key, band.level)
            bands.append((np.asarray(weight, np.float64), off + (j0 - wav.order) / 2.0, sup, step))
    if not bands:
        return np.zeros((1, 1, 1)), np.zeros(3, np.int64), (np.zeros(3), np.zeros(3))
    lo = np.min([off for _, off, _, _ in bands], axis=0)
    hi = np.max([off + s * (np.array(w.shape) + sup) for w, off, sup, s in bands], axis=0)
    origin = np.floor(lo / BLOCK).astype(np.int64)
    count = np.ceil(hi / BLOCK).astype(np.int64) - origin
    sums = np.zeros(tuple(count))
    for weight, off, sup, s in bands:
        part = weight
        for axis in range(3):
            b = origin[axis] + np.arange(count[axis])
            k_lo = np.clip(np.floor((b * BLOCK - off[axis]) / s - sup[axis]).astype(np.int64) + 1, 0, None)
            k_hi = np.minimum(np.ceil(((b + 1) * BLOCK - off[axis]) / s).astype(np.int64) - 1,
                              weight.shape[axis] - 1)
            prefix = np.concatenate([np.zeros_like(np.take(part, [0], axis=axis)), np.cumsum(part, axis=axis)],
                                    axis=axis)
            upper = np.take(prefix, np.clip(k_hi + 1, 0, None), axis=axis)
            lower = np.take(prefix, np.minimum(k_lo, weight.shape[axis]), axis=axis)
            # prefix differences of sums >= 0; rounding can leave them a hair below zero
            part = np.maximum(upper - lower, 0.0) * _broadcast(k_hi >= k_lo, axis)
        sums += part
    return sums, origin, clip_box(sums, origin)


def clip_box(sums, origin) -> tuple:
    """``(lo, hi)`` (x, y, z) in grid-0 fine coordinates around the blocks with a non-zero sum."""
    idx = np.argwhere(sums > 0)
    if not len(idx):
        return np.zeros(3), np.zeros(3)
    box_lo = (origin + idx.min(axis=0)) * BLOCK
    box_hi = (origin + idx.max(axis=0) + 1) * BLOCK
    return box_lo[::-1].astype(float), box_hi[::-1].astype(float)


def _broadcast(flags, axis):
    shape = [1, 1, 1]
    shape[axis] = len(flags)
    return flags.reshape(shape)


def content_cells(wv: WaveletVolume, origin, shape, every: bool = False):
    """(Z, Y, X) uint8 per grid-0 fine cell ``origin + index``: 1 where a non-zero voxel of the source
    volume reaches, 0 where none does; None when the model does not know its content.  ``every``: 1 where
    every voxel whose B-spline (of any group) reaches the cell is non-zero, so that clamping the fine
    coefficients to content changes nothing there (docs/raytracing.md §3, mixed bricks).

    The approximating model of every coefficient, ``sum_k v_k N_j(x - k)`` over the voxels v, is zero
    on a cell that no non-zero voxel's B-spline reaches; a thresholded model is not (truncated
    wavelets ring there, docs/raytracing.md §4).  The ray tracer renders those cells as empty.
    """
    if wv.content_mask is None:
        return None
    j0 = wv.groups[0].wavelet.order
    shifts = [((j0 - g.wavelet.order) / 2.0, g.wavelet.order) for g in wv.groups]  # grid-0 = own + shift
    # voxel k reaches own cells [k, k + j), grid-0 cells [k + s, k + j + s): cell c from k = c + a .. c + b
    a = int(np.floor(-max(s + j for s, j in shifts))) + 1
    b = int(np.ceil(1 - min(s for s, _ in shifts))) - 1
    origin, shape = np.asarray(origin, np.int64), np.asarray(shape, np.int64)
    window = np.asarray(wv.content_mask.box(origin + a, shape + b - a), bool)  # the voxels that reach
    combine = np.logical_and if every else np.logical_or
    for axis in range(3):  # any (every) voxel of [c + a, c + b]: the window's b - a + 1 shifts along the axis combined
        n = window.shape[axis] - (b - a)
        out = window[(slice(None),) * axis + (slice(0, n),)].copy()
        for shift in range(1, b - a + 1):
            combine(out, window[(slice(None),) * axis + (slice(shift, shift + n),)], out=out)
        window = out
    return np.ascontiguousarray(window).view(np.uint8)


def cell_blocks(cells) -> np.ndarray:
    """Per block of BLOCK^3 cells (the cells' box a whole number of blocks), whether any cell is set."""
    Z, Y, X = (n // BLOCK for n in cells.shape)
    return cells.reshape(Z, BLOCK, Y, BLOCK, X, BLOCK).any(axis=(1, 3, 5))


def reached_blocks(wv: WaveletVolume, bricks) -> np.ndarray | None:
    """(n, SUPER, SUPER, SUPER) bool per block (z, y, x) of each brick ``bricks`` (n, 3) (z, y, x brick indices):
    whether a non-zero voxel of the source volume reaches a cell of it (:func:`content_cells`); None when the model
    does not know its content.  Computed a brick layer at a time (docs/raytracing.md §8)."""
    if wv.content_mask is None:
        return None
    bricks = np.asarray(bricks, np.int64)
    out = np.zeros((len(bricks), SUPER, SUPER, SUPER), bool)
    for bz in np.unique(bricks[:, 0]):
        sel = np.flatnonzero(bricks[:, 0] == bz)
        lo = bricks[sel].min(axis=0)
        count = bricks[sel].max(axis=0) - lo + 1
        blocks = cell_blocks(content_cells(wv, lo * BLOCK * SUPER, count * BLOCK * SUPER))
        per = blocks.reshape(count[0], SUPER, count[1], SUPER, count[2], SUPER).transpose(0, 2, 4, 1, 3, 5)
        out[sel] = per[tuple((bricks[sel] - lo).T)]
    return out


def warn_below_tolerance(wv: WaveletVolume, bound: float, tol: float, told: set):
    """Warn when no line integral through the model can reach the absolute tolerance ``tol``: ``bound`` bounds
    what a ray integrates per world unit (the field's largest block bound, times what shading can add), so no ray
    gathers more than it times the volume's diagonal, and skipping may then pass every block of every ray (a black
    image, e.g. micrometre spacing at the default 1e-3).  Once per tolerance and bound in ``told`` (a tracer's: a
    render of another transfer function, shading or detail has its own bound)."""
    limit = bound * float(np.linalg.norm(np.multiply(wv.shape, wv.spacing)))
    key = (tol, float(f"{limit:.3g}"))
    if not 0 < limit < tol or key in told:
        return
    told.add(key)
    why = (f"every line integral of this model is at most {limit:.3g} (its largest value times its diagonal), below "
           f"the absolute tolerance {tol:g}, so the image may be black: give a tolerance well below it, e.g. ")
    smaller = f"{limit * 1e-3:.1g}"
    warn_outside(ClwaveWarning(f"{why}tolerance={smaller}", cli=f"{why}--tolerance {smaller}"))


def warn_packed(step: float, length: float, tol: float, told: set):
    """Warn when an X-ray's absolute tolerance ``tol`` is below what a scalar model's packed pool holds its line
    integrals to: each decoded coefficient within ``step / 2`` of its float, so the field too (partition of unity),
    and a line integral within that times ``length``, the diagonal of the bricks' box (docs/raytracing.md §10,
    "Memory"). Once per tolerance in ``told``."""
    limit = step / 2 * length
    key = ("packed", tol)
    if not tol < limit or key in told:
        return
    told.add(key)
    why = (f"this X-ray's pixels may be off by up to {limit:.3g} (its units: value times length), more than the "
           f"tolerance {tol:g}: its model's bricks are packed to 16 bits (a step of {step:.3g}), and a line integral "
           f"sums that rounding along the ray; ")
    warn_outside(ClwaveWarning(f"{why}for closer pixels trace it with field='wavelet', which is not packed",
                               cli=f"{why}for closer pixels add --field wavelet, which is not packed (--tolerance is "
                                   f"{tol:g} unless given)"))


def warn_empty(segments: int, told: set):
    """Warn when no ray of a render met the model's content (``segments`` 0: a black or transparent image that
    reports nothing wrong, trial26), naming what makes one.  Once a tracer (``told``)."""
    if segments or "empty" in told:
        return
    told.add("empty")
    line = ("no ray met the model's content (0 segments), so the image is empty: the camera looks past it (target, "
            "extent), a clip cuts it away, it is a needle thinner than a pixel from here (axes in different units), "
            "or it is fainter than the tolerance")
    warn_outside(ClwaveWarning(line + " (target=, extent=, clip=, spacing=, tolerance=)",
                               cli=line + " (--extent, --clip-box/--clip-plane, --spacing, --tolerance)"))
