"""The occupancy of the coarsest approximation: which of its coefficients hold content at the centre of their
refinement (the level rule of docs/raytracing.md §8), kept in a ``.clw`` file as a summary of the content mask
that the staged tracer's coarse stage reads at once (docs/chunked.md §4, docs/raytracing.md §9).

Level-L coefficient k of a group spans fine cells ``o_L + 2^L k .. o_L + 2^L (k + j)``; the ``2^L`` voxels at the
centre of its refinement start at :func:`central_start` ``+ 2^L k``, so the level's coefficients share the voxels
out, each voxel to one coefficient.
"""

from __future__ import annotations

import numpy as np

from ..model.bspline import bspline


def central_start(wavelet, level: int) -> int:
    """The first voxel of level-``level`` coefficient 0's central block of ``2^level`` voxels (per axis): the
    refinement's fine B-splines are voxels ``o_L .. o_L + (2^L - 1) j``, and the ``2^L`` at their centre start
    ``(2^L - 1)(j - 1) // 2`` after the first."""
    return wavelet.offset("a", level) + (2 ** level - 1) * (wavelet.order - 1) // 2


def any_blocks(fine, step: int) -> np.ndarray:
    """Bool (``fine.shape // step``): whether any of each ``step``^3 block of the C-ordered bool array ``fine``
    is set.  One axis at a time from the innermost, whose blocks of 2, 4 or 8 bytes are read as one integer: numpy's
    reduction over three strided axes at once is far slower (docs/benchmarks.md §7, set-up)."""
    n = [v // step for v in fine.shape]
    if step == 1:
        return np.ascontiguousarray(fine)
    rows = np.ascontiguousarray(fine).reshape(-1, step)
    if step in WORDS:
        rows = rows.view(WORDS[step])[:, 0] != 0
    else:
        rows = rows.any(axis=1)
    rows = rows.reshape(n[0] * step * n[1], step, n[2]).any(axis=1)
    return rows.reshape(n[0], step, n[1] * n[2]).any(axis=1).reshape(n)


#: unsigned integers as wide as 2, 4 and 8 bools: a block of the innermost axis read at once (:func:`any_blocks`)
WORDS = {2: np.uint16, 4: np.uint32, 8: np.uint64}


class OccupancyGrid:
    """The occupancy of a group's level-``level`` coefficients (bool, ``shape``: the band's), accumulated from
    boxes of the content mask in any order (:meth:`add`): coefficient k is occupied where a voxel of its central
    block is non-empty, the content mask OR-reduced over the blocks."""

    def __init__(self, wavelet, level: int, shape):
        self.step, self.first = 2 ** level, central_start(wavelet, level)
        self.grid = np.zeros(tuple(int(n) for n in shape), bool)

    def add(self, start, block):
        """OR in the blocks that the box ``block`` (bool, z, y, x) at voxel ``start`` meets."""
        start, n = np.asarray(start, np.int64), np.array(block.shape)
        if not n.all():
            return
        lo = (start - self.first) // self.step  # the blocks the box meets: lo .. hi - 1
        hi = (start + n - 1 - self.first) // self.step + 1
        padded = np.zeros(tuple((hi - lo) * self.step), bool)
        at = start - self.first - lo * self.step
        padded[tuple(slice(a, a + m) for a, m in zip(at, n))] = block
        blocks = any_blocks(padded, self.step)
        keep = tuple(slice(max(-a, 0), b - a - max(b - s, 0)) for a, b, s in zip(lo, hi, self.grid.shape))
        self.grid[tuple(slice(max(a, 0), min(b, s)) for a, b, s in zip(lo, hi, self.grid.shape))] |= blocks[keep]

    @property
    def bits(self) -> np.ndarray:
        """The grid packed along x, as a :class:`~clwave.model.mask.ContentMask` holds its bits."""
        return np.packbits(self.grid, axis=2)


def mass_on_occupied(occupied: np.ndarray, wavelet, level: int) -> np.ndarray:
    """Per level-``level`` coefficient (``occupied``'s shape): the share of its B-spline's mass (its integral) that
    lies over occupied central blocks, a product of per-axis shares.  Coefficient k + m's central block spans
    ``central_start - o_L + 2^L m .. + 2^L`` of coefficient k's support, in fine cells (docs/raytracing.md §9)."""
    from scipy.ndimage import correlate1d

    j, step = wavelet.order, 2 ** level
    at = (central_start(wavelet, level) - wavelet.offset("a", level)) / step  # coarse units
    reach = int(max(np.ceil(at), np.ceil(j - at)))  # the blocks k + m, |m| <= reach, that its support meets
    ends = np.clip(at + np.arange(-reach, reach + 2), 0, j)
    # the integral of N_j from 0 to x is sum_k N_{j+1}(x - k) (de Boor, A Practical Guide to Splines, ch. X)
    integral = sum(bspline(j + 1, ends - k) for k in range(j + 1))
    weights = np.diff(integral).astype(np.float32)
    share = occupied.astype(np.float32)
    for axis in range(3):  # out[k] = sum over m of weights[m] share[k + m], share 0 beyond the band
        share = correlate1d(share, weights, axis=axis, mode="constant")
    return share
