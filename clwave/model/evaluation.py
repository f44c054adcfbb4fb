"""The continuous model at points (:meth:`WaveletVolume.evaluate` / ``gradient``, docs/model.md §4).

Two ways give the same sum.  The band sum adds every band's basis functions at each point, reading the kept
coefficients where they are stored: about ``sum over bands of prod S`` reads a point (3,865 for cubic at 3
levels), nothing made beforehand.  The fine path synthesises the fine B-spline coefficients of the region the
points need (:func:`~clwave.model.transform.synthesize`) and reads j³ of them a point.  ``method="auto"`` takes the
fine path where its synthesis, a cost of about the region's size, is repaid by the points (:func:`_pays`);
the band sum stays the independent float64 oracle of the ray tracer's bricks (``method="bands"``), which come
from the synthesis.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from ..errors import InputError
from .geometry import world_points, world_to_fine
from .transform import Band, band_reads, band_sum, crop_to_grid, synthesis_boxes, synthesize

METHODS = ("auto", "bands", "fine")

#: the most bytes of fine coefficients (float64, each channel of the group) one synthesis makes and the model
#: keeps a group; the points of a larger region go through in slabs along z of at least 8 cells, each made in
#: turn (its synthesis peaks at a few times its size, docs/model.md §4), and with ``method="auto"`` a slab still
#: larger (a region wider than 1,024² in y-x for one channel) takes the band sum
REGION_BYTES = 128 << 20

#: regions are whole multiples of this many fine indices per axis: points near those of a call before reuse
#: its region
REGION_STEP = 8

#: the cost rule's price of synthesising, per coefficient of each level's box (:func:`synthesis_boxes`), in reads of
#: the band sum (one basis function's value at one point, a stored coefficient found among the kept ones); a read of
#: the fine coefficients is priced one too (measured on orders 2-6, docs/benchmarks.md §17)
SYNTHESIS_PRICE = 3.5


def evaluate(wv, points, derivative: bool, method: str = "auto") -> np.ndarray:
    """The model of every kept coefficient at world points (N, 3): values (N, C), or world gradients (N, C, 3)."""
    if method not in METHODS:
        raise InputError(f"method={method!r} is not one of {', '.join(map(repr, METHODS))}")
    pts = world_points(points)
    out = np.zeros((len(pts), wv.channels, 3) if derivative else (len(pts), wv.channels))
    for gi, g in enumerate(wv.groups):
        fine = world_to_fine(pts, g.wavelet.order, wv.shape, wv.spacing, wv.origin)  # (z, y, x)
        acc = (_band_total(g, fine, derivative) if method == "bands"
               else _fine_total(wv, gi, fine, derivative, method == "fine"))
        if derivative:
            acc = acc[..., ::-1] / np.asarray(wv.spacing)[::-1]  # fine (z,y,x) -> world (x,y,z)
        out[:, list(g.channels)] = acc
    return out


def _band_total(group, fine, derivative) -> np.ndarray:
    """The band sum at fine points (N, 3): (N, C) or (N, C, 3) in fine (z, y, x)."""
    acc = np.zeros((len(fine), len(group.channels), 3) if derivative else (len(fine), len(group.channels)))
    for number, (band, span) in enumerate(zip(group.bands, group.band_slices())):
        if span.stop > span.start:  # a band with nothing kept adds nothing
            acc += band_sum(group.wavelet, band, SparseBand(group, number), fine, derivative)
    return acc


def _fine_total(wv, gi, fine, derivative, always) -> np.ndarray:
    """The fine path where it pays (or ``always``), the band sum elsewhere, slab by slab."""
    g = wv.groups[gi]
    j, channels = g.wavelet.order, len(g.channels)
    acc = np.zeros((len(fine), channels, 3) if derivative else (len(fine), channels))
    reach = synthesis_boxes(g.wavelet, g.bands)[-1]
    # a point reads the coefficients cell - j + 1 .. cell per axis; one far beyond the reach is clipped to just
    # outside it first (its floor may not fit an int64)
    cell = np.floor(np.clip(fine, np.asarray(reach[0]) - j, np.asarray(reach[1]) + j)).astype(np.int64)
    live = np.flatnonzero(np.all((cell >= reach[0]) & (cell - (j - 1) < reach[1]), axis=1))  # elsewhere zero
    summed = []  # the points of the slabs that take the band sum, summed in one pass (each pass sets up every band)
    for chosen, region in _slabs(cell[live], j, channels, reach):
        points = live[chosen]
        kept = wv._fine.get(gi)
        if kept is None or not _holds(kept, region):
            over = int(np.prod(region[1] - region[0])) * channels * 8 > REGION_BYTES  # a slab wider than the bound
            if not always and (over or not _pays(g, len(points), region)):
                summed.append(points)
                continue
            kept = wv._fine[gi] = synthesize(g.wavelet, g.bands, partial(group_box, g), region)
        coeffs, start = kept
        acc[points] = band_sum(g.wavelet, Band(0, "aaa", coeffs.shape[:3], 0), coeffs, fine[points] - start,
                               derivative)
    if summed:
        points = np.concatenate(summed)
        acc[points] = _band_total(g, fine[points], derivative)
    return acc


def _holds(kept, region) -> bool:
    """Whether the kept fine coefficients ``(coeffs, start)`` cover ``region`` (lo, hi)."""
    start = np.asarray(kept[1])
    return bool(np.all(region[0] >= start) and np.all(region[1] <= start + kept[0].shape[:3]))


def _slabs(cell, j, channels, reach):
    """``(selection, region)`` per slab of the points' cells (n, 3), ``region`` the (lo, hi) of the fine indices its
    points read, rounded out to multiples of :data:`REGION_STEP` and cut to the model's ``reach``: one slab where
    that region holds at most :data:`REGION_BYTES`, else slabs along z whose regions do (at least a step thick)."""
    if not len(cell):
        return
    step = REGION_STEP

    def region(cells):
        lo = (cells.min(axis=0) - (j - 1)) // step * step
        hi = -(-(cells.max(axis=0) + 1) // step) * step
        return np.maximum(lo, reach[0]), np.minimum(hi, reach[1])

    lo, hi = region(cell)
    layer = int(np.prod(hi[1:] - lo[1:])) * channels * 8  # bytes of one z layer of the region
    if int(hi[0] - lo[0]) * layer <= REGION_BYTES:
        yield slice(None), (lo, hi)
        return
    thickness = max(step, (REGION_BYTES // layer - step) // step * step)  # cells a slab; its region is <= + step
    slab = cell[:, 0] // thickness
    order = np.argsort(slab, kind="stable")
    edges = np.flatnonzero(np.diff(slab[order])) + 1
    for chosen in np.split(order, edges):
        yield chosen, region(cell[chosen])


def _pays(group, n_points, region) -> bool:
    """Whether synthesising ``region`` and reading j³ fine coefficients a point costs less than the band sum of
    ``n_points``: prod S reads a point in each band that keeps something (:data:`SYNTHESIS_PRICE`; the channels
    count alike on both sides).  It prices this call alone: what the next call reuses is a gain it leaves out."""
    wav = group.wavelet
    synthesis = SYNTHESIS_PRICE * sum(int(np.prod(hi - lo)) for lo, hi in synthesis_boxes(wav, group.bands, region))
    per_point = sum(band_reads(wav, b) for b, span in zip(group.bands, group.band_slices()) if span.stop > span.start)
    return synthesis + n_points * wav.order ** 3 < n_points * per_point


def group_box(group, number, lo, hi) -> np.ndarray:
    """Band ``number`` of ``group`` on the index box [lo, hi) per axis, (..., C) float64, zeros where nothing is
    kept or beyond the band (what :func:`synthesize` reads)."""
    band = group.bands[number]
    lo, hi = np.asarray(lo, np.int64), np.asarray(hi, np.int64)
    if group.positions is None:  # every coefficient stored: the band's block of the value table, cut to the box
        values = np.moveaxis(group.values[:, band.start:band.start + band.size].reshape((-1,) + band.shape), 0, -1)
        return crop_to_grid(values, tuple(-lo), tuple(hi - lo)).astype(np.float64)
    out = np.zeros(tuple(hi - lo) + (len(group.channels),))
    span = group.band_slices()[number]
    index = np.column_stack(np.unravel_index(group.positions[span] - band.start, band.shape))
    inside = np.flatnonzero(np.all((index >= lo) & (index < hi), axis=1))
    out[tuple((index[inside] - lo).T)] = group.values[:, span.start + inside].T
    return out


class SparseBand:
    """Band ``number`` of ``group`` (at least one coefficient kept) read where it is stored, for
    :func:`band_sum`: ``[iz, iy, ix]`` (broadcast index arrays inside the band) gives the (..., C) coefficients,
    zero where none is kept."""

    def __init__(self, group, number):
        band = group.bands[number]
        self.shape = band.shape + (len(group.channels),)
        self.band, self.values = band, group.values
        span = slice(band.start, band.start + band.size) if group.positions is None else group.band_slices()[number]
        self.positions = None if group.positions is None else group.positions[span]
        self.first = span.start

    def __getitem__(self, index) -> np.ndarray:
        iz, iy, ix = index
        ny, nx = self.band.shape[1:]
        flat = (iz * ny + iy) * nx + ix  # the position in the band
        if self.positions is None:
            return np.moveaxis(self.values[:, self.first + flat], 0, -1)
        found = np.minimum(np.searchsorted(self.positions, flat + self.band.start), len(self.positions) - 1)
        kept = self.positions[found] == flat + self.band.start
        return np.where(kept[..., None], np.moveaxis(self.values[:, self.first + found], 0, -1), 0.0)
