"""Mixed bricks of the ray tracer's B-spline field (docs/raytracing.md §3, §4).

A brick where content and empty voxels meet is expanded at level 0 with the empty voxels' fine coefficients
zeroed (the content clamp).  But in a fine cell that only content voxels' B-splines reach, the clamp zeroes
nothing: the field there is the unclamped one, which is exactly the brick's field at its own (coarser) level,
since refining a B-spline expansion is exact.  So such a brick keeps a second, **coarse** slot at that level, and
the ray crosses the brick's cells of that coarser lattice as pieces: a piece whose fine cells are all reached by
content alone, and where alpha cannot dip below 0 (the least Bernstein coefficient of alpha's polynomial on that
coarse cell is at least 0: the same reason as the fine segments of §3), is one coarse segment read from the
coarse slot; any other piece is marched cell by cell on the clamped fine slot.  Both give the same function.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pyopencl.array as cla

from ..device.constants import BRICK
from ..model.bspline import bspline
from .bounds import content_cells
from .classified import bernstein_matrix


@lru_cache
def bernstein(j: int) -> np.ndarray:
    """(j, j): row k the Bernstein coefficient k (degree j - 1, on the cell [0, 1]) of the polynomial piece
    ``sum_r w_r N_j(u + r)`` of order j, per weight r (the coefficient r cells before the cell's last,
    docs/model.md §1): the pieces' values at j points, taken to Bernstein coefficients."""
    u = np.linspace(0.0, 1.0, j)
    return bernstein_matrix(2 * u - 1) @ np.stack([bspline(j, u + r) for r in range(j)], axis=1)


def alpha_floors(coef, wavelet) -> np.ndarray:
    """(n, n, n): per cell of a brick's lattice box ``coef`` (n + j - 1 per axis, z, y, x) the least Bernstein
    coefficient of its polynomial piece: the field is at least that on the cell (convex hull)."""
    j = wavelet.order
    m = bernstein(j)[:, ::-1]  # per window position q = j - 1 - r
    out = np.asarray(coef, np.float64)
    for axis in range(3):  # separably: each window of j along the axis times the matrix (a Bernstein axis added)
        out = np.lib.stride_tricks.sliding_window_view(out, j, axis=axis) @ m.T
    return out.min(axis=(-3, -2, -1))


def mixed_pieces(wv, lay, alt, lattices, alpha, pool, spill) -> tuple:
    """Per slot (int32 (slots, 4)): its coarse slot, the first of its pieces' flags, the pieces per axis (-1, 0,
    0, 0 where the slot is not a mixed brick's fine slot), and the flags (uint8, 1: the piece is marched on the
    coarse slot), for the fine slots ``alt >= 0`` whose coarse slot is ``alt`` (docs/raytracing.md §3).

    ``lay``: :func:`clwave.raytrace.bricks.layout`; ``lattices``: per level its knot lattice; ``alpha``: the
    group holding alpha (None: none); the pool on the device, or the scratch file (:class:`~.passes.Spill`).
    Counted a brick layer at a time (the content mask read a layer of bricks' cells at once).
    """
    mixes = np.zeros((len(alt), 4), np.int32)
    mixes[:, 0] = -1
    flags, slots, offset = [], [], 0
    fine = np.flatnonzero(alt >= 0)
    bricks = lay["bricks"]
    for bz in np.unique(bricks[fine, 0]):
        sel = fine[bricks[fine, 0] == bz]
        lo = bricks[sel].min(axis=0)
        count = bricks[sel].max(axis=0) - lo + 1
        inner = None
        for s in sel:
            coarse, b = int(alt[s]), bricks[s]
            if inner is None and coarse != s:  # a clamped brick: where only content voxels reach
                inner = content_cells(wv, lo * BRICK, count * BRICK, every=True).astype(bool)
            level = int(lay["levels"][coarse])
            step, origin = 2 ** level, float(lattices[level][0])  # one origin on every axis
            lead = int((BRICK * b[0] - origin) % step)  # the brick's first cell in its first coarse cell
            n = -(-(lead + BRICK) // step)
            cells = np.ones((n * step,) * 3, bool)
            at = tuple(slice(BRICK * (k - o), BRICK * (k - o + 1)) for k, o in zip(b, lo))
            if coarse != s:  # else an unclamped brick mixed with itself: alpha alone decides
                cells[lead:lead + BRICK, lead:lead + BRICK, lead:lead + BRICK] = inner[at]
            mixes[s] = (coarse, offset, n, 0)
            slots.append(s)
            flags.append(cells.reshape(n, step, n, step, n, step).all(axis=(1, 3, 5)))
            offset += n ** 3
    if alpha is not None:  # and where alpha's Bernstein coefficients are >= 0: the alpha boxes read at once
        need = [i for i, f in enumerate(flags) if f.any()]
        shapes = [lay["count"][alt[slots[i]], alpha] for i in need]
        boxes = _alpha_boxes(pool, spill, [int(lay["offset"][alt[slots[i]], alpha]) for i in need],
                             [int(np.prod(shape)) for shape in shapes])
        for i, shape, box in zip(need, shapes, boxes):
            flags[i] &= alpha_floors(box.reshape(shape), wv.groups[alpha].wavelet) >= 0
    return mixes, (np.concatenate([f.astype(np.uint8).ravel() for f in flags]) if flags else np.zeros(1, np.uint8))


def _alpha_boxes(pool, spill, starts, sizes) -> list:
    """The alpha lane of the pool elements ``start .. start + size`` per box: from the device in one gather and one
    copy (a copy per box waited on the queue each time), or from the scratch file."""
    if not starts:
        return []
    if pool is None:
        out = []
        for start, size in zip(starts, sizes):
            box = np.empty((size, 4), np.float32)
            spill.read_into(start, box)
            out.append(box[:, 3])
        return out
    index = np.concatenate([4 * (start + np.arange(size)) + 3 for start, size in zip(starts, sizes)])
    flat = pool.reshape(-1)
    values = cla.take(flat, cla.to_device(pool.queue, index.astype(np.int64))).get()
    return np.split(values, np.cumsum(sizes)[:-1])
