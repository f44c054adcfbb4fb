"""Mixed bricks of the ray tracer's B-spline field (docs/raytracing.md §3, §4).

A brick where content and empty voxels meet is expanded at level 0 with the empty voxels' fine coefficients
zeroed (the content clamp).  But in a fine cell that only content voxels' B-splines reach, the clamp zeroes
nothing: the field there is the unclamped one, which is exactly the brick's field at its own (coarser) level,
since refining a B-spline expansion is exact.  So such a brick keeps a second, **coarse** slot at that level, and
the ray crosses the brick as pieces, parts of that coarser lattice's cells ``PIECE`` fine cells a side: a piece whose
fine cells are all reached by content alone, and where alpha cannot dip below 0 (the least Bernstein coefficient
of alpha's polynomial on that part of the coarse cell is at least 0: the same reason as the fine segments of §3),
is read from the coarse slot; a piece that no content voxel reaches is passed (the clamped field is 0 there); any
other is marched cell by cell on the clamped fine slot.  Both slots give the same function.  A coarse cell with
one rim cell in it keeps its other parts on the coarse slot, and the march crosses a run of pieces with one flag
on one slot, in segments of that slot's lattice.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pyopencl.array as cla

from ..device.constants import BRICK
from ..io.progress import progress
from ..model.bspline import bspline
from ..threads import checkpoint
from .bounds import content_cells
from .classified import bernstein_matrix
from .lod import any_blocks

#: a piece's side in fine cells (at most the coarse cell's): the host count on hydrogen 256^3 at 0.1 % gave the
#: mixed bricks 0.76 of their all-fine segments with whole coarse cells (8), 0.65 with 4 and 0.60 with 2
#: (docs/raytracing.md §3)
PIECE = 2

#: the most cells whose floors are found at once (their Bernstein coefficients held as float64: j^3 each)
CELLS = 8192

#: the most mixed bricks whose pieces are counted at once (their cells held as bytes: up to 24^3 each at level 3)
CHUNK = 512


@lru_cache
def bernstein(j: int, part: int = 0, parts: int = 1) -> np.ndarray:
    """(j, j): row k the Bernstein coefficient k (degree j - 1) of the polynomial piece ``sum_r w_r N_j(u + r)`` of
    order j on the part ``[part, part + 1] / parts`` of the cell [0, 1], per weight r (the coefficient r cells
    before the cell's last, docs/model.md §1): the piece's values at j points of the part, taken to Bernstein
    coefficients on it."""
    v = np.linspace(0.0, 1.0, j)
    u = (part + v) / parts
    return bernstein_matrix(2 * v - 1) @ np.stack([bspline(j, u + r) for r in range(j)], axis=1)


def alpha_floors(coef, wavelet, parts: int = 1, where=None) -> np.ndarray:
    """(..., n p, n p, n p) for ``parts`` p: per cell of a brick's lattice box ``coef`` (..., n + j - 1 per axis, z,
    y, x; leading axes: bricks) cut into p^3 equal parts, the least Bernstein coefficient of the cell's polynomial
    on that part: the field is at least that there (convex hull).  A part's coefficients are convex combinations
    of the whole cell's (subdivision), so only a cell whose own floor is negative is cut, and only where ``where``
    (..., n, n, n) is set (elsewhere its parts get the cell's floor)."""
    j = wavelet.order
    boxes = np.asarray(coef, np.float64).reshape(-1, *np.shape(coef)[-3:])
    per = max(1, CELLS // int(np.prod(np.subtract(boxes.shape[1:], j - 1))))  # boxes at once
    out = np.concatenate([_box_floors(boxes[s:s + per], bernstein(j)[:, ::-1]) for s in range(0, len(boxes), per)])
    lead = np.shape(coef)[:-3] + out.shape[1:]
    out = np.repeat(out.reshape(-1, 1), parts ** 3, axis=1)
    if parts > 1:
        cut = np.stack([bernstein(j, q, parts)[:, ::-1] for q in range(parts)])
        cells = np.lib.stride_tricks.sliding_window_view(boxes, (j, j, j), axis=(1, 2, 3))  # (boxes, n, n, n, j, j, j)
        dips = np.flatnonzero((out[:, 0] < 0) & (True if where is None else np.ravel(where)))
        for start in range(0, len(dips), 4096):
            at = np.unravel_index(dips[start:start + 4096], cells.shape[:4])
            out[dips[start:start + 4096]] = _cell_floors(cells[at], cut)
    b = len(lead) - 3
    out = out.reshape(lead + (parts,) * 3).transpose(*range(b), b, b + 3, b + 1, b + 4, b + 2, b + 5)
    return out.reshape(lead[:b] + tuple(n * parts for n in lead[b:]))


def _box_floors(boxes, m) -> np.ndarray:
    """(boxes, n, n, n): per cell of each box (boxes, n + j - 1 per axis) the least Bernstein coefficient of its
    polynomial (m: (j, j), row c coefficient c by window position).  One axis at a time, x, y then z, over the
    box's windows along it: a window's sums are shared by the cells holding it, not redone per cell; each sum runs
    over the window in order, the arithmetic of :func:`_cell_floors`."""
    x = boxes[..., None]  # last axis: the coefficients so far, per axis done
    for axis in (3, 2, 1):
        n = x.shape[axis] - len(m) + 1
        window = [x[(slice(None),) * axis + (slice(k, k + n),)][..., None] for k in range(len(m))]
        acc = window[0] * m[:, 0]
        for k in range(1, len(m)):
            acc = acc + window[k] * m[:, k]
        x = acc.reshape(*acc.shape[:-2], -1)
    return x.min(axis=-1)


def _cell_floors(cells, m) -> np.ndarray:
    """(cells, p^3): per cell (cells, j, j, j) and part the least Bernstein coefficient (m: (p, j, j) per part its
    matrix by window position), one axis at a time."""
    x = np.einsum("nijk,rck->nrijc", cells, m)
    x = np.einsum("nrijc,qbj->nqribc", x, m)
    x = np.einsum("nqribc,pai->npqrabc", x, m)
    return x.reshape(len(cells), len(m) ** 3, -1).min(axis=2)


def mixed_pieces(wv, lay, alt, lattices, alpha, pool, spill, lock, abandon=None) -> tuple:
    """Per slot (int32 (slots, 4)): its coarse slot, the first of its pieces' flags, the pieces per axis and a
    piece's side in fine cells (-1, 0, 0, 0 where the slot is not a mixed brick's fine slot), and the flags (uint8,
    1: the piece is marched on the coarse slot; 2: no content voxel reaches it, so that the clamped field is 0 there
    and the march passes it; 0: marched on the fine slot), for the fine slots ``alt >= 0`` whose coarse slot is
    ``alt`` (docs/raytracing.md §3).  The pieces of a brick are the :data:`PIECE`-cell parts of the coarse cells that
    hold its cells, from the first of those coarse cells.

    ``lay``: :func:`clwave.raytrace.bricks.layout`; ``lattices``: per level its knot lattice; ``alpha``: the
    group holding alpha (None: none); the pool on the device, or the scratch file (:class:`~.passes.Spill`);
    ``lock``: the pool's device's ``ComputeContext.launch_lock``, held by the gather (pyopencl's take kernel).
    Counted a brick layer at a time (the content mask read a layer of bricks' cells at once), given up between two
    (``abandon``, :func:`~clwave.threads.checkpoint`).
    """
    mixes = np.zeros((len(alt), 4), np.int32)
    mixes[:, 0] = -1
    fine = np.flatnonzero(alt >= 0)
    if not len(fine):
        return mixes, np.zeros(1, np.uint8)
    bricks, coarse = lay["bricks"], alt[fine]
    levels = lay["levels"][coarse]
    step = 2 ** levels
    # the brick's first cell in its first coarse cell (one lattice origin on every axis), the coarse cells that
    # hold its cells per axis, and the pieces per axis
    lead = np.remainder(BRICK * bricks[fine, 0] - lattices[levels, 0].astype(np.float64), step).astype(np.int64)
    side = np.minimum(PIECE, step)
    k = -(-(lead + BRICK) // step) * step // side
    mixes[fine] = np.stack([coarse, np.cumsum(k ** 3) - k ** 3, k, side], axis=1)
    flags, empty = [None] * len(fine), [None] * len(fine)
    # a brick layer at a time: the content mask read for its cells at once
    for bz in progress(np.unique(bricks[fine, 0]), desc="mixed bricks"):
        checkpoint(abandon)
        layer = np.flatnonzero(bricks[fine, 0] == bz)
        lo = bricks[fine[layer]].min(axis=0)
        count = bricks[fine[layer]].max(axis=0) - lo + 1
        inner = reach = None
        if np.any(coarse[layer] != fine[layer]):  # a clamped brick: where only content voxels reach, where any does
            inner = _brick_cells(content_cells(wv, lo * BRICK, count * BRICK, every=True), count)
            reach = _brick_cells(content_cells(wv, lo * BRICK, count * BRICK), count)
        kinds = np.stack([lead[layer], side[layer], k[layer]], axis=1)
        for key in np.unique(kinds, axis=0):  # the bricks of one kind, at most CHUNK at once
            same = layer[np.all(kinds == key, axis=1)]
            for group in np.split(same, np.arange(CHUNK, len(same), CHUNK)):
                f, e = _piece_flags(coarse[group] != fine[group], inner, reach, bricks[fine[group]] - lo,
                                    *map(int, key))
                for i, a, b in zip(group, f, e):
                    flags[i], empty[i] = a, b
    if alpha is not None:  # and where alpha's Bernstein coefficients are >= 0: the alpha boxes read at once
        need = [i for i, f in enumerate(flags) if f.any()]
        shapes = [lay["count"][coarse[i], alpha] for i in need]
        boxes = _alpha_boxes(pool, spill, lock, [int(lay["offset"][coarse[i], alpha]) for i in need],
                             [int(np.prod(shape)) for shape in shapes])
        wavelet = wv.groups[alpha].wavelet
        for shape in {tuple(shape) for shape in shapes}:  # the boxes of one shape at once
            same = [i for i, other in enumerate(shapes) if tuple(other) == shape]
            n = shape[0] - wavelet.order + 1
            parts = len(flags[need[same[0]]]) // n
            stacked = np.stack([flags[need[i]] for i in same])
            some = stacked.reshape(-1, n, parts, n, parts, n, parts).any(axis=(2, 4, 6))
            floors = alpha_floors(np.stack([boxes[i].reshape(shape) for i in same]), wavelet, parts, some)
            for i, floor in zip(same, floors):
                flags[need[i]] &= floor >= 0
    return mixes, np.concatenate([(f + 2 * e).astype(np.uint8).ravel() for f, e in zip(flags, empty)])


def _brick_cells(cells, count) -> np.ndarray:
    """(Z, Y, X, BRICK, BRICK, BRICK) the cells of a box of ``count`` bricks, brick by brick."""
    return cells.astype(bool).reshape(count[0], BRICK, count[1], BRICK, count[2], BRICK).transpose(0, 2, 4, 1, 3, 5)


def _piece_flags(clamped, inner, reach, at, lead: int, side: int, k: int) -> tuple:
    """(m, k, k, k) per brick at ``at`` (brick index in ``inner``, ``reach``) whose first cell is ``lead`` into its
    first coarse cell: whether only content voxels reach each piece's crossed cells (an unclamped brick, not
    ``clamped``: all of them), and whether none does (unclamped: none of them)."""
    m, n = len(at), k * side
    mine = (slice(None),) + (slice(lead, lead + BRICK),) * 3
    cells, unreached = np.ones((m, n, n, n), bool), np.ones((m, n, n, n), bool)  # beyond the brick too
    unreached[mine] = False
    if inner is not None:
        own = tuple(at[clamped].T)
        cells[mine][clamped], unreached[mine][clamped] = inner[own], ~reach[own]
    inside = np.zeros((n, n, n), bool)
    inside[mine[1:]] = True
    crossed = any_blocks(inside, side)  # the others are never crossed
    return ~any_blocks(~cells.reshape(m * n, n, n), side).reshape(m, k, k, k) & crossed, \
        ~any_blocks(~unreached.reshape(m * n, n, n), side).reshape(m, k, k, k) & crossed


def _alpha_boxes(pool, spill, lock, starts, sizes) -> list:
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
    with lock:  # the context's take kernel is shared by its threads: its arguments set and enqueued at once
        values = cla.take(flat, cla.to_device(pool.queue, index.astype(np.int64)))
    values = values.get()
    return np.split(values, np.cumsum(sizes)[:-1])
