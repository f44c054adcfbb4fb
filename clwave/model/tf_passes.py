"""The passes a transfer function makes over a volume (docs/model.md §5, docs/chunked.md §1): one read for an
"auto" window's strided subsample (:func:`auto_window`) and a colour volume's range (:func:`rgb_scale`), each chunk of
a chunked volume read once (:func:`scan`), and the classification itself, a block of voxels at a time over threads
(:func:`classified`), each piecewise-linear function of the voxels' values evaluated by :class:`PiecewiseLinear`."""

from __future__ import annotations

import itertools
import math

import numpy as np

from ..errors import InputError
from ..io.progress import dask_progress
from ..threads import cores, thread_map
from .volume import is_dask

#: Percentiles of the finite values that ``window="auto"`` maps to 0 and 1.
AUTO_PERCENTILES = (0.5, 99.5)
#: ``window="auto"`` looks at a strided subsample of at most this many values.
AUTO_SAMPLES = 1 << 21
CHUNK = 1 << 16          # voxels per work item (the float64 temporaries stay in cache)
THREADED_MIN = 1 << 20   # below this many voxels classify runs in one thread


def auto_window(values) -> tuple:
    """(lo, hi) = 0.5 and 99.5 percentiles of the finite values (strided subsample).

    Falls back to (min, max) when those percentiles coincide, and to
    (v - 0.5, v + 0.5) for a constant input.
    """
    v = np.asarray(values).reshape(-1)
    if v.size > AUTO_SAMPLES:
        v = v[::math.ceil(v.size / AUTO_SAMPLES)]
    v = v[np.isfinite(v)].astype(np.float64)
    if v.size == 0:
        raise InputError('window "auto" found no finite values; give a window (lo, hi)')
    lo, hi = (float(p) for p in np.percentile(v, AUTO_PERCENTILES))
    if not hi > lo:
        lo, hi = float(v.min()), float(v.max())
    if not hi > lo:
        lo, hi = lo - 0.5, lo + 0.5
    return (lo, hi)


def rgb_scale(lo, hi) -> np.ndarray:
    """The range of each channel of a colour volume whose channels span ``lo`` .. ``hi`` (one value a channel): 1, 255
    or 65535, the colour's three together and an alpha by its own (a 0 .. 1 mask beside colour in 0 .. 255 stays
    0 .. 1, docs/model.md §5)."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    colour = _sample_range(lo[:3].min(), hi[:3].max(), "colour")
    return np.array([colour] * 3 + ([_sample_range(lo[3], hi[3], "alpha")] if len(lo) == 4 else []))


def _sample_range(lo, hi, what) -> float:
    if lo < 0:
        raise InputError(f"RGB(A) volume has negative {what} values (min {lo:g}); colour and alpha channels "
                         "must lie in [0, 1], [0, 255] or [0, 65535]")
    for top in (1.0, 255.0, 65535.0):
        if hi <= top:
            return top
    raise InputError(f"RGB(A) volume {what} values reach {hi:g}; colour and alpha channels must lie in "
                     "[0, 1], [0, 255] or [0, 65535]")


def classified(data, paint, threads):
    """(z, y, x, 4) float32: ``paint`` over the voxels of ``data`` (z, y, x[, c]), CHUNK at a time."""
    n = math.prod(data.shape[:3])
    values = data.reshape(n, -1)
    out = np.empty((n, 4), dtype=np.float32)
    run_chunks(n, lambda s, e: paint(values[s:e], out[s:e]), threads)
    return out.reshape(data.shape[:3] + (4,))


def scan(data, sample, extrema):
    """(strided subsample or None, minima or None, maxima or None: one a channel) of ``data`` (z, y, x[, c]): the
    subsample is the voxels whose flat index is a multiple of ceil(voxels / AUTO_SAMPLES), as
    ``data.reshape(n, c)[::step]`` (in another order for a Dask array, which is read once, chunk by chunk)."""
    if not (sample or extrema):
        return None, None, None
    shape = data.shape[:3]
    step = math.ceil(math.prod(shape) / AUTO_SAMPLES)

    def of_block(block, start):
        channels = [block[..., c] for c in range(block.shape[3])] if block.ndim == 4 else [block]
        return (sampled(block, start, shape, step) if sample else None,  # a channel at a time: 4x quicker than axis=0
                [c.min() for c in channels] if extrema else None, [c.max() for c in channels] if extrema else None)

    if is_dask(data):
        import dask

        starts = itertools.product(*(np.cumsum((0,) + c[:-1]) for c in data.chunks[:3]))
        with dask_progress():
            found = dask.compute(*(dask.delayed(of_block)(block, start)
                                   for block, start in zip(data.to_delayed().ravel(), starts)))
    else:
        found = [of_block(data, (0, 0, 0))]
    samples, lows, highs = zip(*found)
    return (np.concatenate(samples) if sample else None,
            np.min(lows, axis=0) if extrema else None, np.max(highs, axis=0) if extrema else None)


def sampled(block, start, shape, step):
    """The voxels of ``block`` (z, y, x[, c]), whose first voxel is ``start`` in a grid of ``shape``, with a flat
    (C order) index in the grid that is a multiple of ``step``, in flat order."""
    nz, ny, nx = block.shape[:3]
    z = np.arange(start[0], start[0] + nz)[:, None, None]
    y = np.arange(start[1], start[1] + ny)[None, :, None]
    row = (z * shape[1] + y) * shape[2] + start[2]      # flat index of each row's first voxel
    x = (-row) % step + np.arange(0, nx, step)          # the row's multiples of step, and some past its end
    iz, iy, ix = np.nonzero(x < nx)
    return block[iz, iy, x[iz, iy, ix]]


def run_chunks(n, work, threads=True):
    """work(start, stop) over chunks of CHUNK voxels, in threads (numpy drops the GIL) unless ``threads`` is
    False (a Dask chunk: Dask runs chunks in threads of its own)."""
    starts = range(0, n, CHUNK)
    if n < THREADED_MIN or not threads:
        for s in starts:
            work(s, min(s + CHUNK, n))
        return
    # contiguous runs of chunks per task keep the writes of one thread together
    per = math.ceil(len(starts) / (4 * cores()))

    def task(i):
        for s in starts[i:i + per]:
            work(s, min(s + CHUNK, n))

    thread_map(task, range(0, len(starts), per))


class PiecewiseLinear:
    """Vectorised np.interp for several channels sharing the same x points.

    np.interp searches per element with branches (slow on noisy data, and once
    per channel); here the segment k of every value is found once, branch-free
    (a sum of comparisons for few points, searchsorted for many), and each
    channel is ``f = fp[k] + slope[k] * (x - xp[k])`` with the distance clamped
    at 0 below the first point and a zero slope past the last, so control points
    and values outside the range give the end rows exactly.
    """

    _COMPARE_MAX = 8       # up to this many points, k = sum(x >= xp[j]) beats searchsorted

    def __init__(self, xp, fp):
        xp = np.asarray(xp, dtype=np.float64)
        fp = np.asarray(fp, dtype=np.float64)
        slope = np.zeros_like(fp)
        dx = np.diff(xp)[:, None]
        # a window can round two close points onto one value: that segment has no width
        np.divide(np.diff(fp, axis=0), dx, out=slope[:-1], where=dx > 0)
        self.xp = xp
        self.f0 = [np.ascontiguousarray(fp[:, c]) for c in range(fp.shape[1])]
        self.slope = [np.ascontiguousarray(slope[:, c]) for c in range(fp.shape[1])]

    def segment(self, x):
        """Segment index k (last point <= x, 0 below the first) and distance x - xp[k] >= 0."""
        xp = self.xp
        if len(xp) <= self._COMPARE_MAX:
            k = np.zeros(x.shape, dtype=np.intp)
            above = np.empty(x.shape, dtype=bool)
            for j in range(1, len(xp)):
                np.greater_equal(x, xp[j], out=above)
                k += above
        else:
            k = np.searchsorted(xp, x, side="right")
            k -= 1
            np.maximum(k, 0, out=k)
        d = x - xp.take(k)
        np.maximum(d, 0.0, out=d)
        return k, d

    def channel(self, k, d, c):
        f = self.slope[c].take(k)
        f *= d
        f += self.f0[c].take(k)
        return f

    def key(self, c):
        return self.f0[c].tobytes()
