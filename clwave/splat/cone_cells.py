"""A cone-beam view's slope cells (docs/splatting.md §8): each band's footprint nodes laid one after another
(:func:`pack_nodes`), the cells of 4 nodes a texel made from them on the device (:func:`slope_cells`,
``cl/splat/cone_cells.cl``, with the quasi-interpolant along the slope axes and each node's peak), and the peaks of
ranges of the view's slope cells that bound dropped splats (:func:`grid_cell_peaks`, :func:`cell_range_peaks`)."""

from __future__ import annotations

import sys
from types import SimpleNamespace

import numpy as np
import pyopencl as cl

from ..device import programs
from ..device.kernels import BUFFER, Kernel, zeros
from ..errors import DeviceMemoryError
from ..threads import thread_map
from .spectral import WORK_ROOM
from .stages import GROUP, I32, groups
from .tables import MAX_LEVELS, POOL_GUARD, set_texture_tables


def pack_nodes(g, textures, layer_of, layer_count, count, max_texels, spare=None, refine=None) -> dict:
    """The texture tables of a view (``band_tex``, ``tex_*``; ``layer_textures``, the textures of each layer; the
    pool ``texels`` None, for :func:`slope_cells`): each layer's bands in order, their nodes one after the other at
    the start of ``nodes`` (page-aligned; ``spare``'s where it holds them, fresh memory costing its first touch),
    where ``tex_nodes`` gives each texture's first work-item of ``cl/splat/cone_cells.cl``, its nodes' offset and
    its first node's peak's.  ``count``: the slope grid's nodes (u, v); ``refine``: band -> r, the bands whose nodes
    are that grid's with r steps to its step (default 1; docs/splatting.md §8 "Refined bands")."""
    band_tex = np.full(8 * MAX_LEVELS, -1, np.int32)
    boxes, ints, maps, tex_layer, offset, layer_textures, placed = [], [], [], [], POOL_GUARD, [], []
    tex_nodes, rows, node_offset, peak_offset = [], 0, 0, 0
    for li in range(layer_count):
        first_tex = len(ints)
        for b in g.bands:
            band = (b.level, b.key)
            if layer_of.get(band) != li:
                continue
            tex, r = textures[band], (refine or {}).get(band, 1)
            cells = (int(count[0]) - 1) * (int(count[1]) - 1) * r * r
            K, nv, nu = tex.data.shape
            size = cells * (nv + 2) * (nu + 2) * 4
            if max_texels is not None and offset + size > max_texels:
                raise DeviceMemoryError(
                    f"the footprints of this perspective view need more than {4 * max_texels / 2**20:,.0f} MiB "
                    f"({K} ray slopes a band); render fewer pixels, a narrower cone or a lower omega_s")
            band_tex[b.id] = len(ints)
            tex_layer.append((li, len(ints) - first_tex))
            boxes.append((-tex.centre_u * tex.h_u, (nu - 1 - tex.centre_u) * tex.h_u,
                          -tex.centre_v * tex.h_v, (nv - 1 - tex.centre_v) * tex.h_v))
            ints.append((offset, nu + 2, r, nv + 2))  # cells' texels are 4 floats
            maps.append((tex.centre_u, tex.centre_v, 1.0 / tex.h_u, 1.0 / tex.h_v))
            tex_nodes.append((rows, node_offset, peak_offset, 0))
            placed.append((tex.data, node_offset))
            offset, rows, node_offset = offset + size, rows + cells * (nv + 2), node_offset + tex.data.size
            peak_offset += K
        layer_textures.append(len(ints) - first_tex)
    fits = spare is not None and spare.size >= node_offset
    nodes = spare if fits else _page_aligned(max(int(WORK_ROOM * node_offset), 1))

    def place(job):  # NumPy's copies free the GIL
        data, first = job
        nodes[first:first + data.size].reshape(data.shape)[...] = data

    thread_map(place, placed)
    out = SimpleNamespace()
    set_texture_tables(out, boxes, ints, maps, tex_layer, [])
    return dict(vars(out), texels=None, pool_floats=offset + 2 * POOL_GUARD, node_floats=node_offset,
                band_tex=band_tex, layer_textures=layer_textures, nodes=nodes,
                tex_nodes=np.array(tex_nodes or [(0, 0, 0, 0)], np.int32), rows=rows, peak_count=peak_offset)


_CELLS = Kernel("cone_cells", ("textures", I32), ("grid_u", I32), ("grid_v", I32), ("quasi", I32), ("tex_int", BUFFER),
                ("tex_nodes", BUFFER), ("nodes", BUFFER), ("texels", BUFFER), ("peaks", BUFFER))


def slope_cells(cc, packed: dict, count, quasi: bool, pool=None) -> tuple:
    """``(pool, cell_peaks)``: the texel pool of :func:`pack_nodes`'s tables on the device ``cc``, its slope cells made
    there from the nodes (``cl/splat/cone_cells.cl``; on a CPU device the nodes are read in place), and for
    each texture the largest magnitude over the nodes of each range of the slope grid's cells (``count``;
    :func:`grid_cell_peaks`, :func:`cell_range_peaks`).
    ``quasi``: the nodes' quasi-interpolants along the slope axes (:func:`quasi_interpolant`).  ``pool``: a device
    buffer of that many floats or more to write over (fresh memory costs its first touch, docs/splatting.md §8)."""
    ku, kv = (int(c) for c in count)
    T = len(packed["tex_nodes"])
    floats = packed["pool_floats"]
    if pool is None:  # room for a view somewhat larger, which can then write over it
        pool = cl.Buffer(cc.ctx, cl.mem_flags.READ_WRITE, 4 * max(floats, min(int(WORK_ROOM * floats),
                                                                               cc.info.max_alloc // 4)))
    for start, size in ((0, POOL_GUARD), (floats - 2 * POOL_GUARD, 2 * POOL_GUARD)):  # the guards of zeros
        cl.enqueue_fill_buffer(cc.queue, pool, np.float32(0.0), 4 * start, 4 * size)
    if not packed["rows"]:  # nothing drawn
        return pool, np.zeros((T, kv - 1, kv - 1, ku - 1, ku - 1))
    used = packed["nodes"][:packed["node_floats"]]
    nodes = (cl.Buffer(cc.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.USE_HOST_PTR, hostbuf=used)
             if cc.info.kind == "CPU" else cc.upload(used))
    peaks = zeros(cc.queue, packed["peak_count"], np.uint32)
    _CELLS(programs.build(cc, ["splat/cone_cells.cl"]), cc.queue, groups(packed["rows"]), (GROUP,),
           textures=T, grid_u=ku, grid_v=kv, quasi=int(quasi), tex_int=cc.upload(packed["tex_int"]),
           tex_nodes=cc.upload(packed["tex_nodes"]), nodes=nodes, texels=pool, peaks=peaks)
    peaks, cells = peaks.get().view(np.float32).astype(np.float64), []
    for (_, _, first, _), (_, _, r, _) in zip(packed["tex_nodes"], packed["tex_int"]):
        shape = ((kv - 1) * r + 1, (ku - 1) * r + 1)
        cells.append(grid_cell_peaks(peaks[first:first + shape[0] * shape[1]].reshape(shape), r))
    return pool, cell_range_peaks(np.array(cells))


def idle_pool(cache: dict, key, floats: int):
    """The device pool of another view in ``cache`` that holds ``floats`` and that no view in use holds any more
    (only the cache does), taken from it (should that view come back, its cells are made again), or None."""
    for other, packed in cache.items():
        pool = packed["texels"]
        # references: the cache's, ``pool`` and getrefcount's argument
        if other != key and pool is not None and pool.size >= 4 * floats and sys.getrefcount(pool) <= 3:
            packed["texels"] = None
            return pool
    return None


def _page_aligned(size: int) -> np.ndarray:
    """``size`` float32 zeros starting on a 4 KiB page, so that a CPU device uses them in place
    (:func:`slope_cells`)."""
    block = np.zeros(size + 1024, np.float32)
    first = (-block.ctypes.data % 4096) // 4
    return block[first:first + size]


def grid_cell_peaks(node_peaks, r: int = 1) -> np.ndarray:
    """(k_v - 1, k_u - 1): the largest magnitude over the nodes of each cell of the slope grid, from a texture's
    ``node_peaks`` ((k_v - 1) r + 1, (k_u - 1) r + 1) refined ``r`` times (a grid cell holds (r + 1)^2 of them)."""
    x = np.asarray(node_peaks)
    for axis in (0, 1):  # each grid cell's nodes i r .. (i + 1) r along the axis
        starts = np.arange(0, x.shape[axis] - 1, r)
        x = np.maximum(np.maximum.reduceat(x, starts, axis=axis), np.take(x, starts + r, axis=axis))
    return x


def cell_range_peaks(cell_peaks) -> np.ndarray:
    """``[t, v0, v1, u0, u1]``: texture t's largest magnitude over slope cells ``v0..v1`` by ``u0..u1``
    (``cell_peaks`` (T, cells along v, along u), :func:`grid_cell_peaks`)."""
    T, cv, cu = cell_peaks.shape
    out = np.zeros((T, cv, cv, cu, cu))
    for v0 in range(cv):
        rows = np.maximum.accumulate(cell_peaks[:, v0:], axis=1)  # cells v0..v1, each v1
        for u0 in range(cu):
            out[:, v0, v0:, u0, u0:] = np.maximum.accumulate(rows[:, :, u0:], axis=2)
    return out
