"""A cone-beam view's slope cells (docs/splatting.md §8): each band's footprint nodes laid one after another
(:func:`pack_nodes`), the cells of 4 nodes a texel made from them on the device (:func:`slope_cells`,
``cl/splat/cone_cells.cl``, with the quasi-interpolant along the slope axes and each node's peak), and the peaks of
ranges of cells that bound dropped splats (:func:`cell_range_peaks`)."""

from __future__ import annotations

import sys
from types import SimpleNamespace

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from ..device import programs
from ..device.kernels import BUFFER, Kernel
from ..errors import DeviceMemoryError
from ..threads import thread_map
from .spectral import WORK_ROOM
from .stages import GROUP, I32, groups
from .tables import MAX_LEVELS, POOL_GUARD, set_texture_tables


def pack_nodes(g, textures, layer_of, layer_count, count, max_texels, spare=None) -> dict:
    """The texture tables of a view (``band_tex``, ``tex_*``; ``layer_textures``, the textures of each layer; the
    pool ``texels`` None, for :func:`slope_cells`): each layer's bands in order, their nodes one after the other at
    the start of ``nodes`` (page-aligned; ``spare``'s where it holds them, fresh memory costing its first touch),
    where ``tex_nodes`` gives each texture's first work-item of ``cl/splat/cone_cells.cl`` and its nodes' offset."""
    band_tex = np.full(8 * MAX_LEVELS, -1, np.int32)
    cells = (int(count[0]) - 1) * (int(count[1]) - 1)
    boxes, ints, maps, tex_layer, offset, layer_textures, placed = [], [], [], [], POOL_GUARD, [], []
    tex_nodes, rows, node_offset = [], 0, 0
    for li in range(layer_count):
        first_tex = len(ints)
        for b in g.bands:
            band = (b.level, b.key)
            if layer_of.get(band) != li:
                continue
            tex = textures[band]
            K, nv, nu = tex.data.shape
            size = cells * (nv + 2) * (nu + 2) * 4
            if max_texels is not None and offset + size > max_texels:
                raise DeviceMemoryError(
                    f"the footprints of this perspective view need more than {4 * max_texels / 2**20:,.0f} MiB "
                    f"({K} ray slopes a band); render fewer pixels, a narrower cone or a lower omega_s")
            band_tex[b.level * 8 + b.code] = len(ints)
            tex_layer.append((li, len(ints) - first_tex))
            boxes.append((-tex.centre_u * tex.h_u, (nu - 1 - tex.centre_u) * tex.h_u,
                          -tex.centre_v * tex.h_v, (nv - 1 - tex.centre_v) * tex.h_v))
            ints.append((offset, nu + 2, size // cells, nv + 2))  # cells' texels are 4 floats
            maps.append((tex.centre_u, tex.centre_v, 1.0 / tex.h_u, 1.0 / tex.h_v))
            tex_nodes.append((rows, node_offset))
            placed.append((tex.data, node_offset))
            offset, rows, node_offset = offset + size, rows + cells * (nv + 2), node_offset + tex.data.size
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
                tex_nodes=np.array(tex_nodes or [(0, 0)], np.int32), rows=rows)


_CELLS = Kernel("cone_cells", ("textures", I32), ("ku", I32), ("kv", I32), ("quasi", I32), ("tex_int", BUFFER),
                ("tex_nodes", BUFFER), ("nodes", BUFFER), ("texels", BUFFER), ("peaks", BUFFER))


def slope_cells(cc, packed: dict, count, quasi: bool, pool=None) -> tuple:
    """``(pool, cell_peaks)``: the texel pool of :func:`pack_nodes`'s tables on the device ``cc``, its slope cells made
    there from the nodes (``cl/splat/cone_cells.cl``; on a CPU device the nodes are read in place), and for
    each texture the largest magnitude over the nodes of each range of cells (:func:`cell_range_peaks`).
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
    peaks = np.zeros(T * ku * kv, np.uint32)
    if packed["rows"]:
        used = packed["nodes"][:packed["node_floats"]]
        nodes = (cl.Buffer(cc.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.USE_HOST_PTR, hostbuf=used)
                 if cc.info.kind == "CPU" else cc.upload(used))
        peaks_d = cla.to_device(cc.queue, peaks)
        _CELLS(programs.build(cc, ["splat/cone_cells.cl"]), cc.queue, groups(packed["rows"]), (GROUP,),
               textures=T, ku=ku, kv=kv, quasi=int(quasi), tex_int=cc.upload(packed["tex_int"]),
               tex_nodes=cc.upload(packed["tex_nodes"]), nodes=nodes, texels=pool, peaks=peaks_d)
        peaks = peaks_d.get()
    return pool, cell_range_peaks(peaks.view(np.float32).astype(np.float64).reshape(T, kv, ku))


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


def cell_range_peaks(node_peaks) -> np.ndarray:
    """``[t, v0, v1, u0, u1]``: texture t's largest node magnitude over the nodes of slope cells ``v0..v1`` by
    ``u0..u1`` (each cell's four nodes; ``node_peaks`` (T, k_v, k_u))."""
    T, kv, ku = node_peaks.shape
    out = np.zeros((T, kv - 1, kv - 1, ku - 1, ku - 1))
    for v0 in range(kv - 1):
        for v1 in range(v0, kv - 1):
            rows = node_peaks[:, v0:v1 + 2].max(axis=1)  # (T, k_u)
            for u0 in range(ku - 1):  # cells u0..u1 read nodes u0..u1 + 1
                out[:, v0, v1, u0, u0:] = np.maximum.accumulate(rows[:, u0:], axis=1)[:, 1:]
    return out
