"""The stages of the splatting pipeline on the device (docs/splatting.md §3), one wrapper each.

project -> count -> transpose -> scan -> tile ranges -> transpose -> place -> accumulate.  Each
wrapper launches one kernel of ``cl/splat/`` with its arguments by name; the renderer and the
kernel tests call these same wrappers, and :mod:`clwave.splat.reference` is the NumPy oracle of
each stage.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl
from pyopencl.scan import ExclusiveScanKernel

from ..device import programs
from ..device.constants import TILE, record_uint4s
from ..device.kernels import BUFFER, Kernel, Pace, bands, in_bands
from ..threads import drain

GPU_PIXELS = 1  # pixels per work-item of raster_gpu.cl (CLW_PX)
U32, I32 = np.uint32, np.int32
_PROJECT = Kernel("splat_project", ("n", U32), ("first", U32), ("coef", BUFFER), ("band_tex", BUFFER),
                  ("band_origin", BUFFER), ("step_col", BUFFER), ("step_row", BUFFER), ("tex_box", BUFFER),
                  ("tex_layer", BUFFER), ("layers", BUFFER), ("centre", BUFFER), ("bbox", BUFFER),
                  ("stex", BUFFER), ("count", BUFFER))
_CHUNK_TILES = Kernel("splat_chunk_tiles", ("n", U32), ("chunk", U32), ("chunks", U32), ("tiles", U32),
                      ("textures", U32), ("place", I32), ("first", U32), ("lo", U32), ("hi", U32),
                      ("bbox", BUFFER), ("centre", BUFFER), ("stex", BUFFER), ("values", BUFFER),
                      ("tex_layer", BUFFER), ("layers", BUFFER), ("table", BUFFER), ("records", BUFFER))
_TRANSPOSE = Kernel("transpose_counts", ("rows", U32), ("cols", U32), ("src", BUFFER), ("dst", BUFFER))
_TILE_RANGES = Kernel("tile_ranges", ("tiles", U32), ("textures", U32), ("chunks", U32), ("total", U32),
                      ("offset", BUFFER), ("ranges", BUFFER))
_PROJECT_CONE = Kernel("splat_project_cone", ("n", U32), ("first", U32), ("coef", BUFFER), ("band_tex", BUFFER),
                       ("band_world", BUFFER), ("band_step", BUFFER), ("tex_box", BUFFER), ("tex_layer", BUFFER),
                       ("layers", BUFFER), ("layer_slope", BUFFER), ("cone", BUFFER), ("centre", BUFFER),
                       ("bbox", BUFFER), ("stex", BUFFER), ("count", BUFFER))
_ACCUMULATE_CONE = Kernel("splat_accumulate_cone", ("first_tile", I32), ("layer_count", I32), ("layers", BUFFER),
                          ("layer_slope", BUFFER), ("cone", BUFFER), ("ranges", BUFFER), ("records", BUFFER),
                          ("tex_int", BUFFER), ("tex_map", BUFFER), ("texels", BUFFER), ("fb", BUFFER))
_ACCUMULATE = Kernel("splat_accumulate", ("first_tile", I32), ("layer_count", I32), ("layers", BUFFER),
                     ("ranges", BUFFER), ("records", BUFFER), ("tex_int", BUFFER), ("tex_map", BUFFER),
                     ("texels", BUFFER), ("fb", BUFFER))


TILE_LIST_SHARE = 0.25  # of the device budget, at most, for the tile lists of one chunk of splats
BIN_TABLE_SHARE = 1 / 32  # of the device budget for the three count tables of a pass, unless one chunk needs more


#: binning work-items (chunks of consecutive splats) per compute unit: a GPU needs many; on a CPU
#: each chunk keeps a write position in every (tile, texture) run, and few keep those in cache
CHUNKS_PER_UNIT = dict(GPU=64, CPU=4)

#: work-items per work-group of the kernels of one item each (project, transpose, tile ranges; binning on a GPU),
#: the global size rounded up to whole groups (the kernels skip the items past the end): PoCL builds a kernel anew
#: for each work-group size, and given none it takes one from the global size, so each new splat count or image
#: size cost a build (0.3-0.6 s on 2 cores, docs/splatting.md §3)
GROUP = 256


def groups(n: int, local: int = GROUP) -> tuple:
    """The global size of ``n`` items in whole work-groups of ``local``."""
    return (max(1, -(-n // local)) * local,)


def tile_list_bytes(budget) -> int:
    """The most bytes of tile lists one pass may use within ``budget`` (a
    :class:`~clwave.device.memory.DeviceBudget`): :data:`TILE_LIST_SHARE` of it, in one buffer."""
    return int(min(budget.max_alloc, budget.total * TILE_LIST_SHARE))


def bin_table_bytes(runs: int, budget) -> int:
    """The most bytes of the three uint32 count tables of a pass with ``runs`` (tile, texture) runs: those
    of :func:`bin_chunks` chunks, one chunk at the least."""
    return max(12 * runs, int(budget.total * BIN_TABLE_SHARE) // 12 * 12)


def bin_chunks(n: int, runs: int, info, budget) -> int:
    """Number of chunks of consecutive splats the binning works in (one work-item each).

    Enough for every compute unit of the device (``info``: :class:`clwave.device.context.DeviceInfo`),
    bounded by the splats and by the (tile, texture, chunk) count tables (``runs`` = tiles x
    textures): three of them, uint32, within :data:`BIN_TABLE_SHARE` of ``budget`` and one allocation.
    """
    per_unit = CHUNKS_PER_UNIT["GPU" if info.kind == "GPU" else "CPU"]
    entries = min(budget.max_alloc // 4, int(budget.total * BIN_TABLE_SHARE) // 12)
    return max(1, min(n, per_unit * info.compute_units, entries // runs))


class Stages:
    """The splatting kernels built for one device and channel count.

    ``variant`` is the accumulation kernel: ``"cpu"`` (``cl/splat/raster_cpu.cl``, a work-item per
    tile) or ``"gpu"`` (``cl/splat/raster_gpu.cl``, a work-item per pixel); default by the device.
    ``perspective``: the cone-beam kernels of ``cl/splat/cone.cl`` (docs/splatting.md §8) project and
    accumulate instead, in the same two layouts (a work-item per tile, or per pixel).
    ``tables`` arguments are a view's uploaded :class:`~clwave.splat.tables.ViewTables` by name.
    """

    def __init__(self, cc, channels: int, variant=None, perspective=False):
        self.cc, self.channels, self.perspective = cc, channels, perspective
        self.variant = variant or ("gpu" if cc.info.kind == "GPU" else "cpu")
        uint4s = record_uint4s(channels, perspective)
        defines = dict(CLW_CHANNELS=channels, CLW_RECORD=uint4s)
        if self.variant == "gpu" and not perspective:
            defines["CLW_PX"] = GPU_PIXELS
        if perspective:
            defines["CLW_PERSPECTIVE"] = 1
            if self.variant == "cpu":
                defines["CLW_CONE_TILE"] = 1
        self.kernels = programs.build(cc, ["splat/bin.cl", "splat/cone.cl" if perspective else
                                           f"splat/raster_{self.variant}.cl"], defines)
        self.record_bytes = 16 * uint4s
        # work-items per tile: one on CPUs (raster_cpu.cl, cone.cl), TILE^2 / GPU_PIXELS on GPUs (TILE^2: cone.cl)
        self.accumulate_local = TILE * TILE // (1 if perspective else GPU_PIXELS) if self.variant == "gpu" else 1
        # work-group sizes, fixed per kernel (GROUP, or less where the device allows less for a kernel); binning
        # chunks on a CPU one work-item per group, so that the few chunks spread over the cores
        size = cl.kernel_work_group_info.WORK_GROUP_SIZE
        self.local = {k.name: min(GROUP, self.kernels[k.name].get_work_group_info(size, cc.device))
                      for k in (_PROJECT_CONE if perspective else _PROJECT, _TRANSPOSE, _TILE_RANGES, _CHUNK_TILES)}
        if cc.info.kind != "GPU":
            self.local[_CHUNK_TILES.name] = 1
        if self.variant == "gpu":
            self._scan = cc.generated("exclusive_scan_uint",
                                      lambda: ExclusiveScanKernel(cc.ctx, np.uint32, "a+b", neutral="0"))
        # the rates of the banded stages (in_bands), kept between passes and views
        self.paces = dict(count=Pace(), place=Pace(), accumulate=Pace())

    def _launch(self, kernel, items, tables=None, **args):
        """``kernel`` over ``items`` work-items in whole work-groups of its fixed size."""
        local = self.local[kernel.name]
        kernel(self.kernels, self.cc.queue, groups(items, local), (local,), tables, **args)

    def pair_budget(self, budget) -> int:
        """The most (tile, splat) pairs one pass may bin: their records within :func:`tile_list_bytes`
        of ``budget``, and record indices (pairs x 2 uint4s) within 32 bits."""
        return min(tile_list_bytes(budget) // self.record_bytes, 2**31 - 1)

    def project(self, n, first, coef, tables, centre, bbox, stex, count):
        """Each splat's pixel centre, pixel box, texture and tile count (0: culled)."""
        self._launch(_PROJECT_CONE if self.perspective else _PROJECT, n, tables, n=n, first=first, coef=coef,
                     centre=centre, bbox=bbox, stex=stex, count=count)

    def count(self, n, chunks, tiles, textures, first, bbox, centre, stex, values, tables, counts, pairs=0):
        """Per chunk of consecutive splats, its splats per (tile, texture), chunk-major (``pairs``: the
        (tile, splat) pairs of the n splats, if known, to pace the launches)."""
        self._chunk_tiles(0, n, chunks, tiles, textures, first, bbox, centre, stex, values, tables, counts, counts,
                          pairs)

    def transpose(self, rows, cols, src, dst):
        """``dst`` = the (rows, cols) table ``src`` transposed."""
        self._launch(_TRANSPOSE, rows * cols, rows=rows, cols=cols, src=src, dst=dst)

    def scan(self, counts, starts):
        """Exclusive prefix sums (arrays of uint32).  The CPU variant's are NumPy's, the device's memory being the
        host's: PoCL takes longer to compile pyopencl's scan kernels than to build the rest of a first splat
        (docs/benchmarks.md §22)."""
        if self.variant == "gpu":
            self._scan(counts, starts)
            return
        host = counts.get()
        sums = np.zeros_like(host)
        np.cumsum(host[:-1], dtype=np.uint32, out=sums[1:])
        starts.set(sums)

    def ranges(self, tiles, textures, chunks, total, starts, ranges):
        """Each tile's [start, end) in the records, from the scanned run-major counts."""
        self._launch(_TILE_RANGES, tiles, tiles=tiles, textures=textures, chunks=chunks, total=total, offset=starts,
                     ranges=ranges)

    def place(self, n, chunks, tiles, textures, first, bbox, centre, stex, values, tables, cursors, records, pairs=0):
        """A record per (tile, splat) pair at each chunk's write cursors (chunk-major); ``pairs`` as for count."""
        self._chunk_tiles(1, n, chunks, tiles, textures, first, bbox, centre, stex, values, tables, cursors, records,
                          pairs)

    def accumulate(self, tiles, layer_count, tables, ranges, records, fb):
        """Add every tile's records to the framebuffers ``fb`` of the view's ``layer_count`` layers, in
        bands of tiles of about equal work (a tile's records, and one for its pixels; ``in_bands``)."""
        drain(self.accumulating(tiles, layer_count, tables, ranges, records, fb))

    def accumulating(self, tiles, layer_count, tables, ranges, records, fb):
        """:meth:`accumulate` as a generator yielding between its bands (``kernels.bands``): a tile's sum is one
        work-item's whatever the bands, so the image does not depend on where they fall."""
        local, q = self.accumulate_local, self.cc.queue
        r = ranges.get().reshape(-1, 2).astype(np.int64)
        work = np.concatenate([[0], np.cumsum(r[:, 1] - r[:, 0] + 1)])
        yield from bands(q, lambda first, count: (_ACCUMULATE_CONE if self.perspective else _ACCUMULATE)(
            self.kernels, q, (count * local,), (local,), tables, first_tile=first,
            layer_count=layer_count, ranges=ranges, records=records, fb=fb), tiles, work=work,
            pace=self.paces["accumulate"])

    def _chunk_tiles(self, place, n, chunks, tiles, textures, first, bbox, centre, stex, values, tables, table,
                     records, pairs):
        """Count or place, in launches of a band of splats of every chunk at a time (``in_bands``), a splat
        costing one and its tile pairs."""
        q, chunk = self.cc.queue, -(-n // chunks)
        in_bands(q, lambda lo, count: self._launch(
            _CHUNK_TILES, chunks, tables, n=n, chunk=chunk, chunks=chunks, tiles=tiles,
            textures=textures, place=place, first=first, lo=lo, hi=lo + count, bbox=bbox, centre=centre, stex=stex,
            values=values, table=table, records=records), chunk, work=chunks * (1 + pairs / max(n, 1)),
            pace=self.paces["place" if place else "count"])
