"""The brick-sparse multiresolution B-spline field of the ray tracer (docs/raytracing.md §3).

The thresholded wavelet expansion of a channel group is, near a point, a B-spline expansion on the lattice of level
l, where l + 1 is the finest level with a kept detail whose support reaches there (docs/model.md §4: the synthesis
of the coarser bands is a change of basis).  The grid-0 fine lattice is cut into bricks of :data:`BRICK`^3 cells (a
brick is a superblock of the empty-space bounds); :func:`plan` gives each brick the coarsest such level over every
group, and :func:`build` expands each brick's coefficients at that level on the device, slab of bricks by slab, from
the model's sparse coefficients (never a full-size array), into one pool with a page table.
``cl/raytrace/field_bspline.h`` evaluates it; ``cl/raytrace/raytrace.cl`` cuts rays at each brick's own knot planes,
so segments in smooth bricks are ``2^l`` cells long.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from itertools import product

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
from pyopencl import cltypes
from pyopencl.elementwise import ElementwiseKernel

from ..device import programs
from ..device.constants import BRICK, SUPER
from ..device.context import ComputeContext
from ..device.kernels import BUFFER, Kernel, zero, zeros
from ..device.memory import DeviceBudget, format_size
from ..errors import DeviceMemoryError
from ..io.progress import progress
from ..model.geometry import band_lattice
from ..threads import checkpoint
from .bounds import reached_blocks
from .lod import content_windows, occupancy
from .pieces import mixed_pieces
from .passes import Spill
from .synthesis import GROUP, Part, Synthesis, lanes, synth_axis, whole_groups

ABSENT = -1            #: the level of a brick that no kept support reaches, or only empty voxels


_GATHER = Kernel("gather_bricks", ("pool", BUFFER), ("src", BUFFER), ("src_start", cltypes.int4),
                 ("src_shape", cltypes.int4), ("starts", BUFFER), ("boxes", BUFFER), ("depth", np.int32),
                 ("scale", np.float32), ("lane", np.int32))
_SCATTER = Kernel("scatter_band", ("out", BUFFER), ("out_start", cltypes.int4), ("out_shape", cltypes.int4),
                  ("positions", BUFFER), ("band_start", np.int64), ("band_shape", cltypes.int4), ("values", BUFFER),
                  ("n", np.int32), ("slots", cltypes.int4), ("channels", np.int32), ("lanes", np.int32))
_FLOOR = Kernel("alpha_floor", ("out", BUFFER), ("coef", BUFFER), ("boxes", BUFFER), ("g", np.int32))
_BOUNDS = Kernel("brick_bounds", ("out", BUFFER), ("first", np.int32), ("origin", cltypes.int4),
                 ("coef", BUFFER), ("bricks", BUFFER), ("frames", BUFFER), ("boxes", BUFFER))


@dataclass
class Plan:
    """Which bricks exist and at which lattice level, per detail (z, y, x brick indices from ``origin``).

    Detail L (0 .. levels) drops the kept details of levels 1 .. L (:mod:`clwave.raytrace.lod`).
    """

    origin: np.ndarray   # (3,) brick index of level[:, 0, 0, 0]
    level: np.ndarray    # (details, Z, Y, X) int8: the brick's lattice level, ABSENT where there is no brick
    clamp: np.ndarray    # (details, Z, Y, X) bool: the brick's coefficients at that level are clamped to content
    mixed: np.ndarray    # (Z, Y, X) int8: a clamped full-detail brick's own level where coarser (pieces.py)

    def slots(self) -> tuple:
        """The distinct bricks over every detail, in brick order: (bricks (n, 3) z, y, x, levels (n,), clamped
        (n,), coarse (n,): serving the coarser details, whose segments stay on their level's lattice, pages
        (details, Z, Y, X) int32: each detail's slot of each brick, -1 for none, alt (n,): a mixed brick's coarse
        slot, unclamped at its own level, -1 for none).  An unclamped brick at level l is one slot for every
        coarser detail that has it: its coefficients come from the bands above l alone."""
        at = np.argwhere(self.level != ABSENT)  # (detail, z, y, x)
        flat = np.ravel_multi_index(tuple(at[:, 1:].T), self.level.shape[1:])
        level = self.level[tuple(at.T)].astype(np.int64)
        key = ((flat * 64 + level) * 2 + self.clamp[tuple(at.T)]) * 2 + (at[:, 0] > 0)
        mixed = np.argwhere((self.mixed != ABSENT) & (self.level[0] != ABSENT) & self.clamp[0])
        mixed_flat = np.ravel_multi_index(tuple(mixed.T), self.level.shape[1:])
        coarse_key = (mixed_flat * 64 + self.mixed[tuple(mixed.T)]) * 4
        unique, slot = np.unique(np.concatenate([key, coarse_key]), return_inverse=True)
        pages = np.full(self.level.shape, -1, np.int32)
        pages[tuple(at.T)] = slot[:len(key)]
        alt = np.full(len(unique), -1, np.int64)
        alt[pages[(0, *mixed.T)]] = slot[len(key):]
        bricks = np.stack(np.unravel_index(unique // 256, self.level.shape[1:]), axis=1) + self.origin
        return (bricks, (unique // 4 % 64).astype(np.int64), (unique // 2 % 2).astype(bool),
                (unique % 2).astype(bool), pages, alt)


def plan(wv, details=None, abandon=None) -> Plan:
    """The bricks of a model and their levels at the detail levels ``details`` (default: every one, 0 .. levels;
    the others have no bricks); given up (``abandon``, :func:`~clwave.threads.checkpoint`) between two bands, or two
    brick rows of the content's windows.

    A brick exists where a kept coefficient's support reaches and (for a model that knows its content) some
    occupied coefficient does (:func:`clwave.raytrace.lod.occupancy`); its level is the coarsest lattice that
    holds every group there exactly, no finer than the detail.  A brick where occupied and unoccupied
    coefficients of the detail's level meet is expanded at that level, where the unoccupied are zeroed: at
    full detail, empty voxels' fine coefficients (docs/raytracing.md §4, §8).  Reach is counted with whole
    support boxes, on the safe side: a brick may be finer than needed, never coarser.
    """
    j0 = wv.groups[0].wavelet.order
    bands = []  # (group, band, slice, per axis the first and last brick each index reaches)
    for g in wv.groups:
        for band, sl in zip(g.bands, g.band_slices()):
            off, step, support = band_lattice(g.wavelet, band.key, band.level)
            corner = [off[a] - (g.wavelet.order - j0) / 2.0 + step * np.arange(n) for a, n in enumerate(band.shape)]
            bands.append((g, band, sl, [(np.floor(c / BRICK).astype(np.int64),  # grid-0 (docs/raytracing.md §3)
                                         np.ceil((c + step * support[a]) / BRICK).astype(np.int64) - 1)
                                        for a, c in enumerate(corner)]))
    origin = np.min([[lo[0] for lo, _ in axes] for *_, axes in bands], axis=0)
    shape = tuple(np.max([[hi[-1] for _, hi in axes] for *_, axes in bands], axis=0) - origin + 1)
    reach_by = {}  # per band level (levels + 1: the approximation) the bricks its kept supports reach
    # one band at a time: no per-coefficient array of the whole model
    for g, band, sl, axes in progress(bands, desc="ray tracer plan"):
        checkpoint(abandon)
        positions = g.all_positions()[sl] - band.start
        if not len(positions):
            continue
        m = wv.levels + 1 if band.key == "aaa" else band.level
        reach = _reach(positions, band.shape, [(lo - o, hi - lo) for (lo, hi), o in zip(axes, origin)], shape)
        reach_by[m] = reach_by[m] | reach if m in reach_by else reach
    levels = np.full((wv.levels + 1, *shape), ABSENT, np.int8)
    clamps = np.zeros(levels.shape, bool)
    mixed = np.full(shape, ABSENT, np.int8)
    own_lattice = lattice_of_levels(wv)[:, 3] == 2.0 ** np.arange(wv.levels + 1)  # the groups share it
    for detail in range(wv.levels + 1) if details is None else details:
        present, level = np.zeros(shape, bool), np.full(shape, wv.levels, np.int8)
        for m, reach in sorted(reach_by.items(), reverse=True):  # the finest detail reaching a brick sets its level
            if m > detail:
                present |= reach
                if m <= wv.levels:
                    level[reach] = m - 1
        level[~present] = ABSENT
        if wv.content_mask is not None:
            empty, mixed_windows = content_windows(wv, detail, origin, shape, abandon)
            level[empty] = ABSENT
            clamps[detail] = mixed_windows & (level != ABSENT)
            if detail == 0:  # mixed bricks: the clamped ones whose own level is coarser (pieces.py)
                keep = clamps[0] & (level > 0)
                keep[keep] = own_lattice[level[keep]]
                mixed[keep] = level[keep]
            level[clamps[detail]] = detail
        levels[detail] = level
    return Plan(origin, levels, clamps, mixed)


def _reach(positions, band_shape, axes, shape) -> np.ndarray:
    """The bricks the supports of a band's coefficients at flat ``positions`` reach, as a boolean grid of ``shape``.

    ``axes``: per axis, the first brick (from the grid's origin) and the extent (bricks beyond it) of each index
    along that axis.  Each coefficient marks its class, (first brick, extent) per axis, through one flat index;
    each extent class is then spread over its extent.
    """
    top = [int(extent.max()) + 1 for _, extent in axes]
    classes = [first * n + extent for (first, extent), n in zip(axes, top)]  # per axis and index
    plane = band_shape[1] * band_shape[2]
    kz, rest = np.divmod(positions, plane)
    ky, kx = np.divmod(rest, band_shape[2])
    flat = (classes[0][kz] * (shape[1] * top[1]) + classes[1][ky]) * (shape[2] * top[2]) + classes[2][kx]
    marks = np.zeros(int(np.prod(shape)) * int(np.prod(top)), bool)
    marks[flat] = True
    corners = marks.reshape(shape[0], top[0], shape[1], top[1], shape[2], top[2])
    reach = np.zeros(shape, bool)
    for e in product(*(range(n) for n in top)):
        marked = corners[:, e[0], :, e[1], :, e[2]]
        if marked.any():
            for d in product(*(range(k + 1) for k in e)):
                reach[tuple(slice(k, None) for k in d)] |= marked[tuple(slice(0, n - k) for n, k in zip(shape, d))]
    return reach


@dataclass
class BrickField:
    """The bricks of a model (``FIELD_PARAMS`` of ``cl/raytrace/field_bspline.h``).

    Slot s holds brick ``bricks[s]`` at level ``levels[s]``; its group g is the box of lattice
    coefficients ``boxes[s, g]`` = (nx, ny, nz, first pool element), whose local lattice coordinate
    at grid-0 point x is ``(x - frames[s, g].xyz) * frames[s, g].w``; ``lattices[s]`` is the origin
    (x, y, z) and spacing of the brick's knot planes (every group's, at its level).  The pool is on
    the device (``resident``) or, when it does not fit there, in a scratch file (:class:`Spill`), and the
    renderer uploads the bricks of one region at a time (docs/raytracing.md §6).
    """

    origin: np.ndarray     # (3,) brick index (z, y, x) of the page table's first brick
    shape: tuple           # the page table's shape (Z, Y, X) in bricks
    bricks: np.ndarray     # (slots, 3) brick index (z, y, x)
    levels: np.ndarray     # (slots,) lattice level
    clamped: np.ndarray    # (slots,) bool: coefficients clamped to content at their level
    pages: np.ndarray      # (details, Z, Y, X) int32: each detail's slot of each brick, -1 for none
    frames: np.ndarray     # (slots, groups, 4) float32
    boxes: np.ndarray      # (slots, groups, 4) int32
    lattices: np.ndarray   # (slots, 4) float32
    bounds: np.ndarray     # (slots, SUPER, SUPER, SUPER) per block: the largest |coefficient| reaching it (§4, §8)
    orders: tuple          # the groups' B-spline orders
    seconds: float         # expansion time
    mixes: np.ndarray      # (slots, 4) int32: coarse slot, first piece flag, pieces per axis; -1, 0, 0, 0 (pieces.py)
    pieces: np.ndarray     # uint8 per piece of the mixed bricks: 1 where it is marched on the coarse slot
    pool: cla.Array | None = None   # float4 coefficients on the device, pre-multiplied by 2^(-3l/2) (build's scalar:
    #                                 one float a coefficient)
    spill: Spill | None = None      # or in a scratch file
    _static: dict | None = None     # the per-slot tables on the device, uploaded once
    given_back: bool = False        # whether a render in passes gave back the memory freed while it was made
    device_from: int | None = None  # the least device budget at which build keeps this pool on the device (None:
    #                                 none, it is over one buffer's limit; _check_fits), and its bytes there
    device_pool_bytes: int = 0

    @property
    def resident(self) -> bool:
        return self.pool is not None

    @property
    def pool_bytes(self) -> int:
        return int(self.pool.nbytes if self.resident else self.spill.nbytes)

    def slot_bytes(self) -> np.ndarray:
        """(slots,) pool bytes of each brick (all groups)."""
        return 16 * np.prod(self.boxes[:, :, :3].astype(np.int64), axis=2).sum(axis=1)

    def bound_grid(self, pages, per_slot=None) -> np.ndarray:
        """The block bounds over the page table's box, (Z, Y, X) * SUPER, of the slots ``pages`` (Z, Y, X) picks
        (or any ``per_slot`` (slots, SUPER, SUPER, SUPER, ...) block values so laid out; zero where no brick)."""
        per_slot = self.bounds if per_slot is None else per_slot
        grid = np.zeros((*self.shape, *per_slot.shape[1:]), per_slot.dtype)
        grid[pages >= 0] = per_slot[pages[pages >= 0]]
        return grid.transpose(0, 3, 1, 4, 2, 5, *range(6, grid.ndim)).reshape(
            *(n * SUPER for n in self.shape), *per_slot.shape[4:])

    def tables(self, cc, pages, slots=None) -> dict:
        """The kernel arguments of the field (``FIELD_PARAMS``) with the slots ``pages`` (Z, Y, X) picks: from the
        pool on the device (resident), or only the bricks ``slots`` read from the scratch file, the others
        absent."""
        q = cc.queue
        if slots is None:
            if self._static is None:
                self._static = {name: cla.to_device(q, _one(getattr(self, name)))
                                for name in ("frames", "boxes", "lattices", "mixes", "pieces")}
            return dict(coef=self.pool, pages=cla.to_device(q, pages.astype(np.int32)), page_origin=self.origin[::-1],
                        page_shape=self.shape[::-1], **self._static)
        slots = np.union1d(slots, self.mixes[slots, 0][self.mixes[slots, 0] >= 0])  # and its mixed bricks' coarse
        starts, sizes = self.boxes[slots, 0, 3].astype(np.int64), self.slot_bytes()[slots] // 16
        at = np.concatenate([[0], np.cumsum(sizes)])  # where each brick goes in the region's pool
        pool = cla.empty(q, (_pool_elements(at[-1], self.orders), 4), np.float32)
        # read straight into the mapped buffer (no host copy), a run of bricks that follow each other in the
        # file at a time
        mapped, _ = cl.enqueue_map_buffer(q, pool.data, cl.map_flags.WRITE_INVALIDATE_REGION, 0, pool.shape,
                                          np.float32)
        try:
            breaks = np.flatnonzero(starts[1:] != starts[:-1] + sizes[:-1]) + 1
            for a, b in zip(np.concatenate([[0], breaks]), np.concatenate([breaks, [len(slots)]])):
                if b > a:  # (a region of no bricks, which a transfer function showing 0 marches: none)
                    self.spill.read_into(int(starts[a]), mapped[at[a]:at[b]])
            mapped[at[-1]:] = 0
        finally:
            mapped.base.release(q)
        boxes = self.boxes[slots].copy()
        boxes[..., 3] += (at[:-1] - starts)[:, None].astype(np.int32)
        where = np.full(len(self.levels) + 1, -1, np.int32)  # each slot's place in the region's tables
        where[slots] = np.arange(len(slots), dtype=np.int32)
        mixes = self.mixes[slots].copy()
        mixes[:, 0] = where[mixes[:, 0]]
        pages = np.full(self.shape, -1, np.int32)  # the page table names a mixed brick's fine slot
        coarse_only = self.mixes[:, 0][(self.mixes[:, 0] >= 0) & (self.mixes[:, 0] != np.arange(len(self.mixes)))]
        shown = slots[~np.isin(slots, coarse_only)]
        pages[tuple((self.bricks[shown] - self.origin).T)] = where[shown]
        return dict(coef=pool, pages=cla.to_device(q, pages), page_origin=self.origin[::-1],
                    page_shape=self.shape[::-1], frames=cla.to_device(q, _one(self.frames[slots])),
                    boxes=cla.to_device(q, _one(boxes)), lattices=cla.to_device(q, _one(self.lattices[slots])),
                    mixes=cla.to_device(q, _one(mixes)), pieces=cla.to_device(q, self.pieces))


def _one(arr):
    """At least one row: OpenCL has no empty buffers."""
    return arr if len(arr) else np.zeros((1,) + arr.shape[1:], arr.dtype)


def group_defines(orders) -> dict:
    """The build defines of the channel groups' orders (``ORDER`` in the kernels)."""
    return dict(CLW_GROUPS=len(orders), CLW_ORDERS=",".join(map(str, orders)))


def layout(wv, bricks, levels) -> dict:
    """Per slot (``bricks`` (n, 3) z, y, x at ``levels``, in brick order) and group: the lattice box, its frame,
    its pool offset."""
    levels = np.asarray(levels, np.int64)
    j0 = wv.groups[0].wavelet.order
    step = 2.0 ** levels[:, None]
    base, count, frame = [], [], []
    for g in wv.groups:
        wav, s = g.wavelet, (g.wavelet.order - j0) / 2.0
        off = np.array([wav.offset("a", int(lv)) for lv in range(wv.levels + 1)], float)[levels][:, None]
        u_lo = (BRICK * bricks + s - off) / step          # the brick in the level's lattice coordinates
        u_hi = (BRICK * (bricks + 1) + s - off) / step
        first = np.floor(u_lo).astype(np.int64) - wav.order + 1
        base.append(first)
        count.append(np.ceil(u_hi).astype(np.int64) - first)
        frame.append(off - s + first * step)
    base, count, frame = np.stack(base, 1), np.stack(count, 1), np.stack(frame, 1)  # (slots, groups, 3)
    sizes = np.prod(count, axis=2).reshape(-1)
    offset = np.concatenate([[0], np.cumsum(sizes)])
    if offset[-1] >= 2 ** 31:
        raise DeviceMemoryError(f"{offset[-1]} brick coefficients are more than one pool indexes (2^31); "
                                f"render a cropped or downsampled volume")
    return dict(bricks=bricks, levels=levels, base=base, count=count, frame=frame,
                offset=offset[:-1].reshape(len(bricks), len(wv.groups)), total=int(offset[-1]),
                ends=offset[::len(wv.groups)])  # slot s spans pool elements ends[s] .. ends[s + 1]


def lattice_of_levels(wv) -> np.ndarray:
    """(levels + 1, 4) per lattice level l: the origin (x, y, z) and spacing of the knot planes every group's
    level-l B-splines share (grid-0 coordinates), or the fine lattice where they do not share a coarser one."""
    j0 = wv.groups[0].wavelet.order
    fine = 0.5 if len({g.wavelet.order % 2 for g in wv.groups}) > 1 else 1.0
    out = []
    for lv in range(wv.levels + 1):
        step = 2.0 ** lv
        starts = {(g.wavelet.offset("a", lv) - (g.wavelet.order - j0) / 2.0) % step for g in wv.groups}
        out.append((*(starts.pop(),) * 3, step) if len(starts) == 1 else (0.0, 0.0, 0.0, fine))
    return np.array(out, np.float32)


def build(wv, cc: ComputeContext, budget: DeviceBudget, p: Plan | None = None, scalar=False,
          abandon=None) -> BrickField:
    """Expand the model's bricks on the device, slab of bricks (one brick row along z) by slab.

    Per slab and group the real-line synthesis (``cl/raytrace/expand.cl``) runs from the approximation
    down to the slab's finest brick level, each level cropped to the box its bricks and the next level
    need; after each level the bricks at it are copied into the pool (``gather_bricks``).  The bands
    are cropped from the model's sparse coefficients per slab.  The pool stays on the device when it
    fits the budget with the bounds, else each slab's bricks go to a scratch file (:class:`Spill`).  Raises
    :class:`DeviceMemoryError` before allocating when one slab's work does not fit.  ``scalar``: a model of one
    channel's pool, when it stays on the device, holds one float a coefficient, the channel alone (``CLW_POOL_SCALAR``
    of ``cl/raytrace/bricks.cl``), for post-classification to pack (:class:`~.classified.ScalarRange`).  ``abandon``
    (a ``threading.Event``): once set, :class:`~clwave.threads.Abandoned` before the next slab (or brick layer of
    the mixed bricks' pieces).
    """
    if scalar and wv.channels != 1:
        raise ValueError(f"a scalar pool is for a model of one channel, not {wv.channels}")
    p = p if p is not None else plan(wv)
    bricks, levels, clamped, coarse, pages, alt = p.slots()
    lay = layout(wv, bricks, levels)
    q, orders = cc.queue, tuple(g.wavelet.order for g in wv.groups)
    pool_lanes = 1 if scalar and len(levels) > 0 else 4  # a scalar pool on the device holds one float a coefficient
    device_from = _check_fits(wv, cc, p, lay, budget, pool_lanes)
    resident = device_from is not None and device_from <= budget.total
    scalar = resident and pool_lanes == 1  # else the renderer reads the pool: float4
    synth = Synthesis(cc)
    if len(levels) and levels.min() < wv.levels:  # some brick needs a synthesis step: its programs built apart
        for g, axis in product(wv.groups, range(3)):
            synth.kernels(g, axis)
    kernels = programs.build(cc, ["raytrace/bricks.cl"], group_defines(orders) | (dict(CLW_POOL_SCALAR=None)
                                                                                  if scalar else {}))
    start = time.perf_counter()
    n, G = len(lay["bricks"]), len(wv.groups)
    frames = np.zeros((n, G, 4), np.float32)
    boxes = np.zeros((n, G, 4), np.int32)
    frames[..., :3] = lay["frame"][..., ::-1]
    frames[..., 3] = 2.0 ** -lay["levels"][:, None]
    boxes[..., :3] = lay["count"][..., ::-1]
    boxes[..., 3] = lay["offset"]
    level_lattices = lattice_of_levels(wv)
    lattices = level_lattices[lay["levels"]]
    alpha = next((gi for gi, g in enumerate(wv.groups) if 3 in g.channels), None)
    bounds = zeros(q, (max(n, 1), SUPER, SUPER, SUPER), np.float32)
    pool = spill = None
    if resident:
        pool = cla.empty(q, (_pool_elements(lay["total"], orders),) + (() if scalar else (4,)), np.float32)
        zero(q, pool[lay["total"]:])  # what no brick writes
    else:
        spill = Spill(lay["total"])
    clamp = cc.generated("clamp_to_content", lambda: ElementwiseKernel(
        cc.ctx, "float *grid, const uchar *keep, const int lanes", "if (!keep[i / lanes]) grid[i] = 0.0f",
        "clamp_to_content"))
    # host work on one slab overlaps the device's on the last: uploads do not wait for the queue, and what they
    # read (and a slab's pool on its way to the scratch file) is held until a marker says the slab is done
    slabs, floors, last_slab = lay["bricks"][:, 0], [], None

    def finish(slab):  # the slab's work is done: what it held goes, its pool to the scratch file
        marker, hold, staged = slab
        marker.wait()
        if staged is not None:
            spill.write(*staged)

    for bz in progress(np.unique(slabs), desc="ray tracer bricks"):  # slabs: brick layers along z
        checkpoint(abandon)
        slots, hold = np.flatnonzero(slabs == bz), []
        first, last = int(lay["ends"][slots[0]]), int(lay["ends"][slots[-1] + 1])
        target, base = (pool, 0) if resident else (cla.empty(q, (last - first, 4), np.float32), first)
        for gi in range(G):
            _expand_slab(wv, gi, lay, slots, clamped[slots], cc, synth, kernels, target, base, clamp, hold)
        local = boxes[slots].copy()
        local[..., 3] -= base
        local = _send(q, local, hold)
        at = np.zeros((len(slots), 4), np.int32)
        at[:, :3] = (lay["bricks"][slots] - p.origin)[:, ::-1]
        _BOUNDS(kernels, q, (SUPER ** 3, len(slots)), (SUPER ** 3, 1), out=bounds, first=int(slots[0]),
                origin=p.origin[::-1], coef=target, bricks=_send(q, at, hold),
                frames=_send(q, frames[slots], hold), boxes=local)
        if alpha is not None:  # docs/raytracing.md §3: where alpha may dip below 0, the fine lattice's segments
            floors.append((slots, cla.empty(q, len(slots), np.float32)))
            _FLOOR(kernels, q, (len(slots),), (1,), out=floors[-1][1], coef=target, boxes=local, g=alpha)
        staged = None
        if not resident:
            staged = (first, np.empty((last - first, 4), np.float32))
            hold.append(target)
            target.get_async(q, staged[1])
        if last_slab is not None:
            finish(last_slab)
        last_slab = (cl.enqueue_marker(q), hold, staged)
    if last_slab is not None:
        finish(last_slab)
    q.finish()
    below = np.concatenate([slots[floor.get() < 0] for slots, floor in floors] or [np.zeros(0, np.int64)])
    # full-detail unclamped bricks where alpha may dip below 0: mixed with themselves, alpha checked per piece
    selfish = below[~coarse[below] & ~clamped[below] & (levels[below] > 0) & ~np.isin(below, alt)]
    selfish = selfish[level_lattices[levels[selfish], 3] == 2.0 ** levels[selfish]]  # the groups share the level
    alt[selfish] = selfish
    # the others of full detail: fine segments (docs/raytracing.md §3); the coarser details' keep their level's, alpha
    # clamped at the samples (§8, "Alpha at coarser details")
    lattices[below[~np.isin(below, alt) & ~coarse[below]]] = level_lattices[0]
    mixes, pieces = mixed_pieces(wv, lay, alt, level_lattices, alpha, pool, spill, cc.launch_lock, abandon)
    bounds = bounds.get()[:n]
    cut = np.flatnonzero(clamped & (lay["levels"] == wv.levels))  # the coarsest detail's (docs/raytracing.md §8)
    if len(cut) and (reached := reached_blocks(wv, lay["bricks"][cut])) is not None:
        bounds[cut] *= reached
    return BrickField(p.origin, p.level.shape[1:], lay["bricks"], lay["levels"], clamped, pages, frames, boxes,
                      lattices, bounds, orders, time.perf_counter() - start, mixes, pieces, pool, spill,
                      device_from=device_from, device_pool_bytes=4 * pool_lanes * _pool_elements(lay["total"], orders))


def _pool_elements(total, orders) -> int:
    """The pool's coefficients (``total``: its bricks'), at least the j^3 that a segment in no brick reads from its
    start, times weights 0 (a transfer function that shows the field's 0 marches the data's box where no brick lies,
    docs/raytracing.md §10): zero where no brick writes them, as 0 times what a buffer held may be NaN."""
    return max(int(total), max(orders) ** 3)


def _check_fits(wv, cc, p: Plan, lay, budget, pool_lanes=4) -> int | None:
    """The least device budget at which the pool (``pool_lanes`` floats a coefficient) stays on the device, beside
    the bounds and the expansion's work (None: one buffer cannot hold it); DeviceMemoryError when the
    bounds and the work alone do not fit ``budget``.  A slab's synthesis holds about three boxes of its finest
    level's float4 coefficients at once (the parts, the pairs of one axis step, the output), and two slabs can be
    under way (build's overlap), with their pools when the pool goes to host memory."""
    pool = 4 * pool_lanes * _pool_elements(lay["total"], [g.wavelet.order for g in wv.groups])
    bounds = 4 * SUPER ** 3 * (len(lay["levels"]) + int(np.prod(p.level.shape[1:])))  # per slot, and a grid
    halo = 2 * max(g.wavelet.order for g in wv.groups)
    slab, slab_pool, ends = 0, 0, lay["ends"]
    for bz in np.unique(lay["bricks"][:, 0]):
        sel = np.flatnonzero(lay["bricks"][:, 0] == bz)
        for lv in np.unique(lay["levels"][sel]):  # each level's box holds the bricks at it and finer ones' parents
            bricks = lay["bricks"][sel[lay["levels"][sel] <= lv]]
            extent = (bricks[:, 1:].max(axis=0) - bricks[:, 1:].min(axis=0) + 1) * BRICK
            slab = max(slab, 3 * 16 * int(np.prod(np.ceil((np.append(BRICK, extent) + halo) / 2.0 ** lv))))
        slab_pool = max(slab_pool, 16 * int(ends[sel[-1] + 1] - ends[sel[0]]))
    work = 2 * slab
    if bounds + work + 2 * slab_pool > budget.total or slab / 3 > budget.max_alloc:
        raise DeviceMemoryError(
            f"expanding the bricks of this volume needs at least {format_size(bounds + work + 2 * slab_pool)} on "
            f"{cc.info.name}, which allows {format_size(budget.total)} ({format_size(budget.max_alloc)} per "
            f"buffer); raise --device-memory, crop the volume or pick another --device")
    return pool + bounds + work if pool <= cc.info.max_alloc else None


def _parents(wav, taps, lo, hi) -> tuple:
    """The parent index box (first, last per axis) that the children ``lo .. hi`` of one synthesis step read."""
    firsts, lasts = [], []
    for letter in "ad":
        shift, n = wav.synthesis_shift(letter), len(taps[letter])
        firsts.append(-((shift + n - 1 - lo) // 2))  # ceil((lo - shift - n + 1) / 2)
        lasts.append((hi - shift) // 2)
    return np.min(firsts, axis=0), np.max(lasts, axis=0)


def _band_part(cc, kernels, g, band_no: int, band_slice: slice, lo, hi, hold) -> Part | None:
    """The band's coefficients in the index box lo .. hi (inclusive, z, y, x) on the device, dense, :func:`lanes`
    floats a coefficient with channel c in slot ``g.channels[c]`` (one lane: the channel alone), zero where not
    kept; None where the band keeps nothing in the box's layers.  The kept coefficients of those layers (one
    contiguous run of the sorted positions) are scattered into the box on the device: no dense copy on the host."""
    band, q, n_lanes = g.bands[band_no], cc.queue, lanes(g)
    shape = hi - lo + 1
    a, b = np.maximum(lo, 0), np.minimum(hi + 1, band.shape)
    if np.any(b <= a):
        return None
    if g.positions is None:  # every coefficient stored: the box is a slice of the band
        out = np.zeros((*shape, n_lanes), np.float32)
        values = g.values[:, band.start:band.start + band.size].reshape(-1, *band.shape)
        target = tuple(slice(x - o, y - o) for x, y, o in zip(a, b, lo))
        out[(*target, list(g.channels) if n_lanes == 4 else [0])] = np.moveaxis(
            values[(slice(None), *(slice(x, y) for x, y in zip(a, b)))], 0, -1)
        return Part(_send(q, out, hold), lo, shape)
    plane = band.shape[1] * band.shape[2]
    positions = g.positions[band_slice]
    i, k = np.searchsorted(positions, band.start + np.array([a[0], b[0]]) * plane)
    if k == i:
        return None
    out = zeros(q, (*(int(n) for n in shape), n_lanes), np.float32)
    slots = np.full(4, -1)
    slots[:len(g.channels)] = g.channels if n_lanes == 4 else 0
    _SCATTER(kernels, q, (int(-(-(k - i) // 64) * 64),), (64,), out=out, out_start=lo[::-1], out_shape=shape[::-1],
             positions=_send(q, positions[i:k], hold), band_start=band.start, band_shape=band.shape[::-1],
             values=_send(q, g.values[:, band_slice][:, i:k], hold), n=k - i, slots=slots,
             channels=len(g.channels), lanes=n_lanes)
    return Part(out, lo, shape)


def _expand_slab(wv, gi, lay, slots, clamped, cc, synth, kernels, pool, base, clamp, hold):
    """One group's bricks of one slab into ``pool``, whose first element is pool element ``base``; per slot,
    ``clamped``: coefficients zeroed where unoccupied (docs/raytracing.md §8)."""
    g, q = wv.groups[gi], cc.queue
    wav = g.wavelet
    taps = {"a": (wav.p / np.sqrt(2.0)).astype(np.float32), "d": (wav.q / np.sqrt(2.0)).astype(np.float32)}
    levels = lay["levels"][slots]
    first, last = lay["base"][slots, gi], lay["base"][slots, gi] + lay["count"][slots, gi] - 1
    own = {int(lv): (first[levels == lv].min(axis=0), last[levels == lv].max(axis=0)) for lv in np.unique(levels)}
    need = {min(own): own[min(own)]}
    for lv in range(min(own) + 1, wv.levels + 1):
        lo, hi = _parents(wav, taps, *need[lv - 1])
        if lv in own:
            lo, hi = np.minimum(lo, own[lv][0]), np.maximum(hi, own[lv][1])
        need[lv] = (lo, hi)
    slices = g.band_slices()

    def part(band_no, box):
        return _band_part(cc, kernels, g, band_no, slices[band_no], *box, hold)

    def gather(level, src):
        here = levels == level
        if np.any(sel := here & ~clamped):
            copy(slots[sel], level, src)
        if np.any(here & clamped):  # docs/raytracing.md §8; at the finest level the synthesis is done with
            data = src.data.copy() if level > min(own) else src.data
            keep = occupancy(wv.content_mask, wav, level, src.start, src.shape).view(np.uint8)
            clamp(data.reshape(-1), _send(q, keep, hold), lanes(g))
            copy(slots[here & clamped], level, Part(data, src.start, src.shape))

    def copy(sel, level, src):
        starts = np.zeros((len(sel), 4), np.int32)
        starts[:, :3] = lay["base"][sel, gi][:, ::-1]
        boxes = np.zeros((len(sel), 4), np.int32)
        boxes[:, :3] = lay["count"][sel, gi][:, ::-1]
        boxes[:, 3] = lay["offset"][sel, gi] - base
        n = boxes[:, :3].max(axis=0)
        _GATHER(kernels, q, whole_groups((int(n[0]), int(n[1]), int(n[2]) * len(sel))), GROUP, pool=pool, src=src.data,
                src_start=src.start[::-1], src_shape=src.shape[::-1], starts=_send(q, starts, hold),
                boxes=_send(q, boxes, hold), depth=int(n[2]), scale=2.0 ** (-1.5 * level),
                lane=-1 if lanes(g) == 4 else g.channels[0])

    approx = part(0, need[wv.levels]) or Part(zeros(q, (1, 1, 1, lanes(g)), np.float32), need[wv.levels][0],
                                                np.ones(3, np.int64))
    if wv.levels in own:
        gather(wv.levels, approx)
    d_taps = {k: _send(q, v, hold) for k, v in taps.items()}
    shifts = {k: wav.synthesis_shift(k) for k in "ad"}
    for m in range(wv.levels, min(own), -1):
        parts = {"aaa": approx}
        for band_no, band in enumerate(g.bands):
            if band.level == m and band.key != "aaa" and (detail := part(band_no, need[m])) is not None:
                parts[band.key] = detail
        lo, hi = need[m - 1]
        for axis in range(3):  # array axis z, y, x; keys lose their leading letter per axis done
            merged = {}
            for rest in sorted({key[1:] for key in parts}):
                pair = [(letter, parts[letter + rest]) for letter in "ad" if letter + rest in parts]
                merged[rest] = synth_axis(cc, synth.kernels(g, 2 - axis), pair, axis, d_taps, shifts,
                                           (lo[axis], hi[axis]))
            parts = merged
        approx = parts[""]
        if m - 1 in own:
            gather(m - 1, approx)


def _send(q, arr, hold: list) -> cla.Array:
    """``arr`` copied to the device without waiting for the queue; the host array is held in ``hold`` until the
    caller knows the queue has passed the copy."""
    arr = np.ascontiguousarray(arr)
    hold.append(arr)
    return cla.to_device(q, arr, async_=True)
