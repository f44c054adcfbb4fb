"""Level of detail for the ray tracer's B-spline field (docs/raytracing.md §8).

Detail L drops the kept details of levels 1 .. L: the field is then a B-spline on the level-L lattice (or
coarser, where no kept detail of a coarser level reaches), and a ray crosses it in segments ``2^L`` cells long.
Empty space stays empty by one rule at every level: level-L coefficient k of a group is kept where the
``2^L`` voxels at the centre of its B-spline's refinement hold a non-empty one (:func:`occupancy`); at L = 0
that is the voxel itself (docs/raytracing.md §4).  :func:`content_windows` says per brick whether that clamp
removes anything at detail L; :class:`Detail` is what a render asks for (a level cap and/or a screen-space error
in pixels, after Guthe et al. 2002), and :func:`brick_caps` turns it into a detail per brick for one view.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl.array as cla

from ..device.constants import BRICK, SUPER
from ..errors import InputError, finite_number
from ..io.occupancy import any_blocks, central_start
from ..io.progress import progress
from ..threads import checkpoint
from .bounds import clip_box, superblocks


def occupancy(mask, wavelet, level: int, start, shape) -> np.ndarray:
    """Bool (``shape``): whether level-``level`` coefficient ``start + index`` (z, y, x) of a group with this
    wavelet holds a non-empty voxel at the centre of its refinement (docs/raytracing.md §8).

    Coefficient k's B-spline spans fine cells ``o_L + 2^L k .. o_L + 2^L (k + j)`` (``o_L`` the level's offset,
    docs/model.md §4); the fine B-splines inside it, whose coefficients its subdivision makes, are voxels
    ``o_L + 2^L k .. o_L + 2^L k + (2^L - 1) j``, and the ``2^L`` at their centre start
    ``(2^L - 1)(j - 1) // 2`` after the first: the level's coefficients share the voxels out, each voxel to one.
    At level 0 that is voxel k alone.
    """
    step = 2 ** level
    start, shape = np.asarray(start, np.int64), np.asarray(shape, np.int64)
    return any_blocks(mask.box(central_start(wavelet, level) + step * start, step * shape), step)


def content_windows(wv, level: int, origin, shape, abandon=None) -> tuple:
    """Per brick of the grid at ``origin`` (brick index, z, y, x) of ``shape``: (no group's window holds an
    occupied level-``level`` coefficient, some group's window holds an unoccupied one).

    Group g's window in brick b is its level-L coefficients whose B-splines reach the brick (as
    :func:`clwave.raytrace.bricks.layout` counts them); counted separably a brick row at a time, given up between
    two (``abandon``, :func:`~clwave.threads.checkpoint`).
    """

    j0, mask = wv.groups[0].wavelet.order, wv.content_mask
    has_any, has_all = [], []
    for g in wv.groups:
        wav = g.wavelet
        j, s, step = wav.order, (wav.order - j0) / 2.0, 2.0 ** level
        windows = []
        for axis in range(3):  # per brick along the axis: its first and last coefficient + 1
            b = origin[axis] + np.arange(shape[axis])
            lo = np.floor((BRICK * b + s - wav.offset("a", level)) / step).astype(np.int64) - j + 1
            hi = np.ceil((BRICK * (b + 1) + s - wav.offset("a", level)) / step).astype(np.int64)
            windows.append((lo, hi))
        (zlo, zhi), (ylo, yhi), (xlo, xhi) = windows
        rows_any, rows_all = [], []
        for bz in progress(range(shape[0]), desc="content windows"):  # a brick row at a time: the level's occupancy
            checkpoint(abandon)
            occ = occupancy(mask, wav, level, (zlo[bz], ylo[0], xlo[0]), (zhi[bz] - zlo[bz], yhi[-1] - ylo[0],
                                                                          xhi[-1] - xlo[0]))
            full = occ.all(axis=0, keepdims=True)
            some = occ.any(axis=0, keepdims=True)
            for axis, (lo, hi) in ((1, (ylo - ylo[0], yhi - ylo[0])), (2, (xlo - xlo[0], xhi - xlo[0]))):
                full = _window_counts(full, axis, lo, hi) == (hi - lo).reshape([-1 if a == axis else 1
                                                                                for a in range(3)])
                some = _window_counts(some, axis, lo, hi) > 0
            rows_any.append(some)
            rows_all.append(full)
        has_any.append(np.concatenate(rows_any))
        has_all.append(np.concatenate(rows_all))
    empty = ~np.any(has_any, axis=0)
    mixed = np.any([a & ~b for a, b in zip(has_any, has_all)], axis=0) | np.any([~a for a in has_any], axis=0)
    return empty, mixed & ~empty


def _window_counts(arr, axis, lo, hi) -> np.ndarray:
    """Counts of True in ``arr`` along ``axis`` over ``[lo[i], hi[i])`` per i: a cumulative sum in as few bits
    as the widest window needs (it may wrap around: the differences of a window are exact)."""
    widest = int(np.max(hi - lo))
    dtype = np.uint8 if widest < 2 ** 8 else np.uint16 if widest < 2 ** 16 else np.int64
    shape = list(arr.shape)
    shape[axis] = 1
    sums = np.concatenate([np.zeros(shape, dtype), np.cumsum(arr, axis=axis, dtype=dtype)], axis=axis)
    return np.take(sums, hi, axis=axis) - np.take(sums, lo, axis=axis)


@dataclass(frozen=True)
class Detail:
    """What detail a render asks for: ``level`` caps the lattice level (0: every kept detail; L: the details
    of levels 1 .. L dropped), ``pixels`` (optional) lets a brick go coarser while its level's cells project
    to at most that many pixels (Guthe et al.'s screen-space error; orthographic views: one level for all,
    perspective: per brick, by its nearest point's distance from the eye).  ``Detail()`` is full detail."""

    level: int = 0
    pixels: float | None = None

    @classmethod
    def of(cls, detail, levels: int) -> "Detail":
        """``detail`` as a Detail: None (full), a whole level, or a Detail; InputError naming the range."""
        if detail is None:
            return cls()
        given = detail  # named as the caller wrote it: detail=3, not Detail(level=3, pixels=None)
        if isinstance(detail, (int, np.integer)) and not isinstance(detail, bool):
            detail = cls(int(detail))
        if not isinstance(detail, Detail) or not isinstance(detail.level, (int, np.integer)) \
                or not 0 <= detail.level <= levels:
            raise InputError(f"detail={given!r} must be a level from 0 (full detail) to {levels} (the "
                             f"approximation alone), or clwave.Detail(level=, pixels=)")
        if detail.pixels is not None and not finite_number(detail.pixels, "detail pixels") > 0:
            raise InputError(f"Detail pixels={detail.pixels!r} must be a positive screen-space error")
        return detail


def brick_caps(detail: Detail, levels: int, view, bricks_lo, spacing) -> np.ndarray | int:
    """The detail level of every brick for one view under ``detail.pixels``: the coarsest level (at least
    ``detail.level``) whose cells (``2^l`` fine cells of the largest spacing) project to at most that many
    pixels; an int where one level serves every brick (orthographic views).

    ``bricks_lo``: the bricks' boxes' corners (n, 3) in world (x, y, z) and their edge (``BRICK`` fine cells of
    the spacing, per axis).
    """
    cell = float(max(spacing))
    if not view.perspective:
        pixel = view.pixel  # world units per pixel
        return int(np.clip(np.floor(np.log2(detail.pixels * pixel / cell)), detail.level, levels))
    lo, edge = bricks_lo
    nearest = np.clip(view.eye, lo, lo + edge)
    distance = np.maximum(np.linalg.norm(nearest - view.eye, axis=1), cell)
    pixel = distance * max(view.slope)  # the wider of a cone beam's pixels (View.slope: per unit distance)
    return np.clip(np.floor(np.log2(detail.pixels * pixel / cell)), detail.level, levels).astype(np.int64)


@dataclass
class FieldAt:
    """What a render of the B-spline field reads at one choice of detail: the slot of each brick (``pages``,
    (Z, Y, X), -1 for none) and the picked ``slots``, the block bounds on the device and their superblocks, the
    clip box, the largest bound and the occupied block fraction, the field's tables (resident pools), and per brick
    whether a coarse segment may cross into it (``joins``, :func:`lattice_joins`)."""

    pages: np.ndarray
    slots: np.ndarray
    block_bound: object
    super_bound: object
    super_bound_host: np.ndarray
    super_origin: np.ndarray
    box: tuple
    q_bound: float
    occupied_fraction: float
    field_tables: dict | None
    joins: object


def field_at(field, cc, pages) -> FieldAt:
    """The :class:`FieldAt` of the slots ``pages`` picks from a :class:`~clwave.raytrace.bricks.BrickField`:
    nothing is expanded, only the bounds of the picked slots laid out and uploaded (docs/raytracing.md §8)."""
    bound = field.bound_grid(pages)
    occ_origin = field.origin * SUPER
    super_host, super_origin = superblocks(bound, occ_origin)
    q = cc.queue
    joins = cla.to_device(q, lattice_joins(field, pages))
    return FieldAt(pages, np.unique(pages[pages >= 0]), cla.to_device(q, bound), cla.to_device(q, super_host),
                   super_host, super_origin, clip_box(bound, occ_origin), float(bound.max(initial=0.0)),
                   float(np.mean(bound > 0)), dict(field.tables(cc, pages), joins=joins) if field.resident else None,
                   joins)


def lattice_joins(field, pages) -> np.ndarray:
    """uint8 per brick (Z, Y, X): the spacing of its knot lattice where that is coarser than the fine one and the
    brick is not mixed, else 0.  A segment on a coarse lattice crosses the face into a brick with its own spacing
    (docs/raytracing.md §3, "segments per brick"): bricks of one level share that level's lattice and hold the same
    coefficients where their boxes meet."""
    out = np.zeros(pages.shape, np.uint8)
    slots = pages[pages >= 0]
    spacing = field.lattices[slots, 3]  # the fine lattice's is 1 or 1/2, a coarse one's 2^l
    joined = (field.mixes[slots, 0] < 0) & (spacing >= 2) & (spacing < 256)  # (a byte: levels past 7 do not join)
    out[pages >= 0] = np.where(joined, spacing, 0).astype(np.uint8)
    return out


def pick(field, caps) -> np.ndarray:
    """The slot of each brick (Z, Y, X) at detail ``caps``: one level, or one per brick (Z, Y, X)."""
    if np.ndim(caps) == 0:
        return field.pages[int(caps)]
    return np.take_along_axis(field.pages, np.asarray(caps, np.int64)[None], axis=0)[0]
