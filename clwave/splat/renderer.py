"""Wavelet splatting (paper §4, docs/splatting.md): X-ray images as sums of basis-function footprints.

:class:`SplatRenderer` keeps a model's ranked coefficients on the device, or streams them there in
chunks in importance order where they and a view's working set do not fit its budget
(docs/splatting.md §6); each view's :class:`Accumulator` makes the footprint textures and tables
(:mod:`clwave.splat.tables`) and runs the device stages (:mod:`clwave.splat.stages`) over coefficient
ranges in importance order.  The image is the line integral of each channel in world units
(docs/coordinates.md).
"""

from __future__ import annotations

import time

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
from pyopencl.elementwise import ElementwiseKernel
from pyopencl.reduction import ReductionKernel
from pyopencl.tools import ImmediateAllocator, MemoryPool

from ..device.constants import TILE, record_uint4s
from ..device.context import ComputeContext
from ..device.memory import FRAMEBUFFER_PIXEL_BYTES, check_image, device_budget, format_size, parse_cap, too_little
from ..errors import InputError, finite_number, type_name
from ..io.result import RenderResult
from ..model.conebeam import check_camera, resolve_view, view_record
from ..model.signs import warn_both_signs
from ..model.wavelet import WaveletVolume, check_model
from . import accumulator
from .accumulator import Accumulator
from .coarse import Layer, coarse_plan, footprint_scales
from .ranked import CumulativeEnergy, on_device, ranked_groups
from .stages import BIN_TABLE_SHARE, TILE_LIST_SHARE, Stages, bin_table_bytes, tile_list_bytes
from .perspective import ConeTables, camera_words, depth_range
from .tables import MAX_LEVELS, ViewTables
from .textures import check_omega_s, check_sampling
from ..threads import drain, in_turns, one_at_a_time

COEFFICIENT_BYTES = 32  # on the device: int4 (k_x, k_y, k_z, band) and float4 values (cl/splat/bin.cl)
SPLAT_BYTES = 32  # per splat of a pass: centre float2, pixel box int4, texture int, tile count uint
CONE_SPLAT_BYTES = 40  # perspective: the centre is float4 (col, row, depth, 0)
#: streamed chunks hold at least this many coefficients: below it, a pass's work over every tile (count
#: tables, ranges, framebuffer writes) outweighs its splats
MIN_CHUNK = 1024


class SplatRenderer:
    """Splats any view of a wavelet volume: its ranked coefficients stay on the device, or stream there in
    chunks in importance order where they and the view's working set exceed the device budget.  Several threads may
    render through one at once: views on a device take their turn (docs/coordinates.md §4).

    Parameters
    ----------
    wv : WaveletVolume
    device : str or ComputeContext
    omega_s : float, optional
        Footprint band (paper eq. 35/36); default from the pixel size.
    sampling : "auto", "fft", "spatial" or "cells"
        How footprint textures are made (:func:`clwave.splat.textures.footprints`); "auto" takes
        "cells" for Haar when u or v is a world axis: along that axis (or both) the footprint
        is its 2 exact cells, looked up by nearest sample, and along the other it is sampled
        at 1/(8 P) pixel (:data:`clwave.splat.tables.CELL_REFINE`).  ``meta["texture_sampling"]`` says what ran:
        "fft", "spatial", "cells" (both axes), "cells-u" or "cells-v" (that axis only).
    coarse : float, optional
        Tolerance, relative to the image maximum, for drawing coarse cubic bands into
        coarser framebuffers that are upsampled with the cubic B-spline (docs/splatting.md §4;
        see :func:`clwave.splat.coarse.coarse_plan`); in perspective views, what that leaves of it also drops
        wavelet splats under a bound (docs/splatting.md §8, ``meta["dropped"]``).  None (default): every band at the
        image's pixel, every splat drawn.
    device_memory : int or str, optional
        Cap on the device memory the renderer holds: bytes, or a size such as "2GiB" or "512M"
        (:func:`clwave.device.memory.parse_size`); default the device's memory.  Coefficients that do not
        fit with a view's framebuffers, footprints and tile lists stream in chunks (docs/splatting.md §6);
        ``meta["coefficient_chunks"]`` counts a view's uploads.
    """

    def __init__(self, wv: WaveletVolume, device=None, omega_s=None, sampling="auto", coarse=None,
                 device_memory=None):
        check_model(wv, "splatting")
        if wv.levels >= MAX_LEVELS:
            raise InputError(f"splatting supports up to {MAX_LEVELS - 1} levels, the volume has {wv.levels}")
        omega_s, sampling, coarse = splat_options(omega_s, sampling, coarse)
        warn_both_signs(wv)  # splatting draws line integrals only
        self.wv, self.omega_s, self.sampling, self.coarse = wv, omega_s, sampling, coarse
        self.cc = ComputeContext.get(device)
        self.budget = device_budget(self.cc, device_memory)
        start = time.perf_counter()
        # one build per channel count of the groups: a scalar volume accumulates one channel
        self.stages = {(c, False): Stages(self.cc, c) for c in sorted({len(g.channels) for g in wv.groups})}
        self.pixel_updates = self.cc.generated("pixel_updates", lambda: ReductionKernel(
            self.cc.ctx, np.int64, neutral="0", reduce_expr="a+b", arguments="__global const int4 *bbox",
            map_expr="bbox[i].z < bbox[i].x ? 0 : (long)(bbox[i].z - bbox[i].x + 1) * (bbox[i].w - bbox[i].y + 1)"))
        # a pass that draws some of its splats only: the others' boxes emptied after projection (docs/splatting.md §8)
        self.mask_splats = self.cc.generated("mask_splats", lambda: ElementwiseKernel(
            self.cc.ctx, "int4 *bbox, uint *counts, const uchar *keep",
            "if (!keep[i]) { bbox[i] = (int4)(0, 0, -1, -1); counts[i] = 0; }", "mask_splats"))
        self.compile_seconds = time.perf_counter() - start
        q = self.cc.queue
        # per-pass tables come from a pool that keeps its buffers, and the tile lists from one buffer grown as
        # needed, so a new view does not map (and the OS zero) fresh pages
        self.scratch = MemoryPool(ImmediateAllocator(q))
        self._tile_lists = None
        self.chunk = None  # coefficients per streamed chunk; None while every group's are on the device
        self._resident = None  # per group: (coef, values) device arrays of every coefficient
        self._work = None  # per-splat buffers of a pass, and the streamed chunk's (coef, values)
        self._sizes = None  # the count tables' sizes of the last view
        self._cone_footprints = {}  # perspective views' texture tables, shared by poses of one direction
        self._spectra_work = {}  # their footprint spectra's arrays, written over by the next view's
        self._grown = False  # extend() gave more coefficients than the device arrays hold
        self.groups = ranked_groups(wv)
        self.lock = self.cc.lock  # one view at a time on the device (threads.one_at_a_time)

    def extend(self, wv: WaveletVolume, groups: list):
        """``wv`` in place of the model, and its :func:`ranked_groups` ``groups``, whose tables begin with this
        renderer's coefficients in its order (a file's prefix, then the rest of it: docs/viewer.md §2).  A view
        under way splats on from the device arrays it began with; the next view's :meth:`begin` puts them all
        there."""
        if len(groups) != len(self.groups) or any(
                new["count"] < old["count"] or not all(np.array_equal(getattr(new["table"], f)[: old["count"]],
                                                                      getattr(old["table"], f))
                                                       for f in ("coef", "packed"))
                for old, new in zip(self.groups, groups)):
            raise ValueError("the groups do not begin with this renderer's coefficients")
        self.wv, self.groups, self._grown = wv, groups, True

    def tile_lists(self, nbytes: int):
        """A device buffer of at least ``nbytes`` for the tile lists, kept between chunks and views."""
        if self._tile_lists is None or self._tile_lists.size < nbytes:
            self._tile_lists = None  # released before the larger one is made
            room = max(nbytes, min(nbytes + nbytes // 4, tile_list_bytes(self.budget)))  # room to grow
            self._tile_lists = cl.Buffer(self.cc.ctx, cl.mem_flags.READ_WRITE, room)
        return self._tile_lists

    @property
    def count(self) -> int:
        """Coefficients per channel group (importance order: frames splat ranges of them)."""
        return self.groups[0]["count"] if self.groups else 0

    @property
    def energy(self) -> CumulativeEnergy | np.ndarray:
        """Cumulative coefficient energy (sum of c^2 over channels) of the first group, in importance order, indexed
        like an array (a :class:`~clwave.splat.ranked.CumulativeEnergy`; zeros(1) without groups)."""
        return self.groups[0]["energy"] if self.groups else np.zeros(1)

    # -------------------------------------------------------------- drawing
    def stage(self, channels: int, perspective: bool) -> Stages:
        """The kernels for groups of ``channels`` channels, orthographic or perspective (built on first use)."""
        if (channels, perspective) not in self.stages:
            start = time.perf_counter()
            self.stages[(channels, perspective)] = Stages(self.cc, channels, perspective=perspective)
            self.compile_seconds += time.perf_counter() - start
        return self.stages[(channels, perspective)]

    @one_at_a_time
    def begin(self, camera, upto=None):
        """Start an image of a :class:`Camera` or :class:`ConeBeam` (or its :class:`~clwave.model.camera.View` of this
        model, resolved already): resolve the view, make footprints, zero the framebuffers (an
        :class:`Accumulator`).  ``upto``: the image splats only the first ``upto`` coefficients, so only the bands
        they reach get footprints (a viewer's frame while dragging)."""
        view = resolve_view(camera, self.wv)
        # the world width of a pixel for the coarse framebuffers' error: in perspective the widest, at the far
        # side of the volume (docs/splatting.md §8)
        pixel = max(view.slope) * depth_range(view, self.wv, 0)[1] if view.perspective else view.pixel
        # framebuffer factors (f_u, f_v) of each band that has coefficients (among the first ``upto``), per group:
        # (1, 1) unless drawn coarse; and what they leave of the tolerance.  Planned over every band kind of the
        # model, present or not, so that a prefix, or a worker's share of the coefficients, draws each band as the
        # whole does
        reach = np.inf if upto is None else upto
        scales = footprint_scales(view, self.wv.spacing[::-1])
        bands = [[b for b in g.bands if gr["present"].get((b.level, b.key), np.inf) < reach]
                 for g, gr in zip(self.wv.groups, self.groups)]
        plans = [coarse_plan(g.wavelet.order, {(b.level, b.key == "aaa") for b in g.bands}, pixel, scales, self.coarse,
                             square=not view.perspective) if self.coarse else ({}, 0.0) for g in self.wv.groups]
        factors = [{(b.level, b.key): plan.get((b.level, b.key == "aaa"), (1, 1)) for b in bs}
                   for bs, (plan, _) in zip(bands, plans)]
        layers = [Layer(view, F) for F in sorted({f for fg in factors for f in fg.values()} | {(1, 1)})]
        fb_bytes = sum(layer.view.size[0] * layer.view.size[1] for layer in layers) * FRAMEBUFFER_PIXEL_BYTES
        tiles = sum(-(-layer.view.size[0] // TILE) * -(-layer.view.size[1] // TILE) for layer in layers)
        # before the footprint tables: what the view needs without them (every group's framebuffers and tile
        # ranges, tile lists, count tables, a least chunk), within the budget, and on the host; _plan, with the
        # tables, names the least budget that works
        check_image(self.cc, view.size, fb_bytes, "render a smaller image (at most {n}x{n} here)", self.budget,
                    what="the framebuffer of a {}x{} image",
                    least=self._least_budget(len(self.groups) * (fb_bytes + 8 * tiles), tiles, tiles,
                                             view.perspective))
        per_layer = [[(layer.view, {band for band, f in fg.items() if f == layer.factors}) for layer in layers]
                     for fg in factors]
        if view.perspective:
            tables = [ConeTables(self.wv, gi, ls, self.omega_s, self.sampling, device=self.cc,
                                 max_texels=self.cc.info.max_alloc // 4, cache=self._cone_footprints,
                                 work=self._spectra_work, words=camera_words(camera))
                      for gi, ls in enumerate(per_layer)]
            for g in self.wv.groups:  # after the tables, which refuse a cone too wide before any kernel is built
                self.stage(len(g.channels), True)
        else:
            tables = [ViewTables(self.wv, gi, ls, self.omega_s, self.sampling, device=self.cc,
                                 max_texels=self.cc.info.max_alloc // 4) for gi, ls in enumerate(per_layer)]
        self._prepare(tables, view.size)
        acc = Accumulator(self, view, layers, tables, upto, view_record(camera, view, self.wv.unit))
        if view.perspective and self.coarse:  # what coarsening leaves of the tolerance (docs/splatting.md §8)
            acc.drop_share = [left for _, left in plans]
        return acc

    def texel_pools(self, tables: list) -> list:
        """Each table's texel pool on the device: a perspective view's is made there (:class:`ConeTables`, shared
        by poses that differ by a translation), an orthographic one's uploaded."""
        return [t.texels if isinstance(t, ConeTables) else self.cc.upload(t.texels) for t in tables]

    def render(self, camera) -> RenderResult:
        """The X-ray image of one view (a :class:`Camera` or :class:`ConeBeam`, or its view resolved already: as
        :meth:`begin`) from every coefficient."""
        return RenderResult(*_splat_range(self, camera, 0, self.count))

    def views(self, cameras):
        """:class:`RenderResult` of each camera in turn: the coefficients stay on the device and the kernels
        built, so a view costs its footprints, binning and accumulation only (docs/splatting.md §8)."""
        for camera in cameras:
            yield self.render(camera)

    def render_many(self, cameras, out=None) -> np.ndarray:
        """Images of many views (poses) of one size as an (N, H, W, C) float32 array, or into ``out`` (a float32
        array of that shape, writable, e.g. ``numpy.lib.format.open_memmap`` to stream them to a file); both checked
        before the first view."""
        cameras = list(cameras)
        if not cameras:  # no view gives no image size to make an (N, H, W, C) array of
            raise InputError("render_many got no views: give at least one camera")
        for i, camera in enumerate(cameras):
            check_camera(camera, f"cameras[{i}]")
        sizes = sorted({tuple(camera.size) for camera in cameras})
        if len(sizes) > 1:
            named = ", ".join("x".join(map(str, size)) for size in sizes)
            raise InputError(f"the views have {len(sizes)} image sizes ({named}): render_many takes views of the "
                             "same size (render the others apart)")
        shape = (len(cameras),) + sizes[0] + (self.wv.channels,)
        if out is None:
            out = np.empty(shape, np.float32)
        elif not isinstance(out, np.ndarray) or out.shape != shape or out.dtype != np.float32:
            got = f"{out.dtype} array of shape {out.shape}" if isinstance(out, np.ndarray) else type_name(out)
            raise InputError(f"out is a {got}; the views need float32 {shape}")
        elif not out.flags.writeable:  # else numpy's "assignment destination is read-only" after the first view
            raise InputError("out is read-only (a memmap opened with mode 'r'?): give a writable array, e.g. "
                             "numpy.lib.format.open_memmap(path, mode='w+', dtype=numpy.float32, shape=...)")
        for i, res in enumerate(self.views(cameras)):
            out[i] = res.image
        return out

    # -------------------------------------------------------------- device memory
    def _prepare(self, tables: list, size):
        """The coefficients on the device for a view with these tables: all of them where they fit the budget
        with the view's working set, else a buffer for a chunk of the most that fit (docs/splatting.md §6)."""
        chunk = self._plan(tables, size)
        sizes = tuple(t.tiles * max(t.layer_textures, default=0) for t in tables)
        if sizes != self._sizes:  # count tables of other sizes: the pool's held buffers go
            self.scratch.free_held()
            self._sizes = sizes
        centre = 4 if isinstance(tables[0], ConeTables) else 2  # floats per splat centre
        if chunk != self.chunk or self._grown:  # from all on the device to streamed, another chunk, or more
            self._resident = self._work = None                # coefficients: the last buffers go
            self.chunk, self._grown = chunk, False
        if self._work is not None and self._work["centre"].shape[1] != centre:
            self._work = None
        q = self.cc.queue
        if chunk is None and self._resident is None:
            self._resident = [on_device(self.cc, g["table"]) for g in self.groups]
        if self._work is None:
            n = max(chunk or min(max(g["count"] for g in self.groups), accumulator.PASS_ROWS), 1)
            self._work = dict(centre=cla.empty(q, (n, centre), np.float32), bbox=cla.empty(q, (n, 4), np.int32),
                              stex=cla.empty(q, (n,), np.int32), counts=cla.empty(q, (n,), np.uint32))
            if chunk is not None:
                self._work.update(coef=cla.empty(q, (n, 4), np.int32), values=cla.empty(q, (n, 4), np.float32))

    def _least_budget(self, fixed: int, tiles: int, runs: int, perspective: bool) -> int:
        """The least device budget for a view whose framebuffers, footprint tables and tile ranges take ``fixed``
        bytes (every group's), binned over ``tiles`` tiles in ``runs`` (tile, texture) runs: those, :data:`MIN_CHUNK`
        coefficients with their splats, the count tables at their floor and tile lists for one splat over every
        tile, within the budget's shares for them (:data:`TILE_LIST_SHARE`, :data:`BIN_TABLE_SHARE`)."""
        least = min(MIN_CHUNK, max(g["count"] for g in self.groups))
        base = fixed + (COEFFICIENT_BYTES + (CONE_SPLAT_BYTES if perspective else SPLAT_BYTES)) * least
        one_splat = tiles * max(16 * record_uint4s(len(g.channels), perspective) for g in self.wv.groups)
        return int(max(base / (1 - TILE_LIST_SHARE - BIN_TABLE_SHARE), (base + 12 * runs) / (1 - TILE_LIST_SHARE),
                       one_splat / TILE_LIST_SHARE)) + 1

    def _plan(self, tables: list, size):
        """None when every group's coefficients fit on the device with this view's working set, else the
        coefficients per streamed chunk; a :class:`DeviceMemoryError` naming the least budget that would do
        when not even :data:`MIN_CHUNK` of them fit."""
        b, counts = self.budget, [g["count"] for g in self.groups]
        most, least = max(counts), min(MIN_CHUNK, max(counts))
        runs = max(t.tiles * max(t.layer_textures, default=0) for t in tables)
        perspective = isinstance(tables[0], ConeTables)
        one_splat = max(t.tiles for t in tables) * max(16 * record_uint4s(len(g.channels), perspective)
                                                       for g in self.wv.groups)
        # framebuffers, the view's tables and texel pool, and a pass's tile ranges
        fixed = sum(16 * t.pixels + sum(_bytes(getattr(t, name)) for name in t.names) + 8 * t.tiles
                    for t in tables)
        free = b.total - fixed - tile_list_bytes(b) - bin_table_bytes(runs, b)
        splat_bytes = CONE_SPLAT_BYTES if perspective else SPLAT_BYTES
        rows = min(most, accumulator.PASS_ROWS)
        if COEFFICIENT_BYTES * sum(counts) + splat_bytes * rows <= free and 16 * most <= b.max_alloc:
            return None
        chunk = min(free // (COEFFICIENT_BYTES + splat_bytes), b.max_alloc // 16, most)
        if chunk >= least and tile_list_bytes(b) >= one_splat:
            return int(chunk)
        need = self._least_budget(fixed, max(t.tiles for t in tables), runs, perspective)
        H, W = size
        too_little(self.cc, b, f"a {H}x{W} view needs at least {format_size(need)} of device memory (framebuffers, "
                               f"footprints, tile lists and {least:,} coefficients at a time)",
                   "render a smaller image")


def splat(wv: WaveletVolume, camera, device=None, *, omega_s=None, sampling="auto", coarse=None,
          device_memory=None, scheduler=None, renderer: SplatRenderer | None = None) -> RenderResult:
    """X-ray image of a wavelet volume by wavelet splatting, through a :class:`Camera` (orthographic or
    perspective) or a :class:`ConeBeam` (docs/splatting.md §8).

    Returns a :class:`RenderResult` whose ``image`` (H, W, C) holds the line integral of
    each channel in world units and whose ``meta`` reports the coefficients splatted,
    footprint, binning, accumulation and upsampling times (kernel compile time apart), the
    footprint texture sampling, the framebuffer factors and the coefficient chunks streamed.
    ``omega_s``, ``sampling``, ``coarse`` and ``device_memory`` are those of :class:`SplatRenderer`;
    without ``renderer``, calls on the same model, device and options share one
    (:meth:`WaveletVolume.shared`).  ``scheduler`` (a number of local worker processes, an address or a
    ``distributed.Client``, :mod:`clwave.schedulers`): each worker opens the model's ``.clw`` file and splats an
    equal share of its coefficients, and the image is the sum of theirs (docs/splatting.md §7).
    """
    check_camera(camera)
    if scheduler is not None:
        omega_s, sampling, coarse = splat_options(omega_s, sampling, coarse)  # before any worker starts
        return _splat_on_cluster(wv, camera, scheduler, device, dict(
            omega_s=omega_s, sampling=sampling, coarse=coarse,
            device_memory=parse_cap(device_memory)))
    r = renderer or shared_renderer(wv, device, omega_s, sampling, coarse, device_memory)
    return RenderResult(*_splat_range(r, camera, 0, r.count))


def _splat_range(r: SplatRenderer, camera, first: int, stop: int) -> tuple:
    """``(image, meta)`` of coefficients ``first .. stop`` of each group, in importance order."""
    with r.lock:  # the image's begin and its passes together: another thread's begin may change the chunking
        return drain(_splatting(r, camera, first, stop))


def splat_in_turns(r: SplatRenderer, camera):
    """:func:`splat` of every coefficient with ``r`` as a generator of stages, each under ``r.lock`` and none
    between two (its view's set-up, then ``Accumulator.passes``' binnings and bands of accumulation), that returns
    the :class:`RenderResult`: the same image bit for bit, whatever ``r`` splats between two stages (a viewer's
    saved image taking turns with its tabs' frames, docs/viewer.md §5; its passes' buffers its own).  A
    perspective view that drops splats (``splat_dropping``) is one stage after its set-up: its drops are chosen
    from the whole image."""
    check_camera(camera)
    return RenderResult(*(yield from in_turns(r.lock, _splatting(r, camera, 0, r.count, own=True))))


def _splatting(r: SplatRenderer, camera, first: int, stop: int, own=False):
    """:func:`_splat_range` as a generator yielding between its stages (``own`` as ``Accumulator.passes``)."""
    start = time.perf_counter()
    acc = r.begin(camera)
    if any(acc.drop_share) and r.chunk is None and (first, stop) == (0, r.count):
        acc.splat_dropping()
    else:
        yield
        yield from acc.passes(first, stop - first, own)
    image = acc.image()
    return image, acc.meta(time.perf_counter() - start)


def _splat_on_cluster(wv, camera, scheduler, device, options) -> RenderResult:
    from ..cluster import check_model_file, render_parts, workers_of
    from ..schedulers import client_for

    check_model_file(wv, "splatting")  # before any worker starts
    with client_for(scheduler) as client:  # which checks the scheduler before starting anything
        shares = workers_of(client)
        results = render_parts(client, _splat_share, wv.source, [(i, shares) for i in range(shares)], device,
                               options, camera)
    metas = [m for _, m in results]
    meta = dict(metas[0], workers=shares, device_budget=[m["device_budget"] for m in metas],
                seconds={k: max(m["seconds"][k] for m in metas) for k in metas[0]["seconds"]},
                **{k: int(sum(m[k] for m in metas)) for k in ("coefficients", "tile_pairs", "pixel_updates",
                                                               "coefficient_chunks")})
    return RenderResult(np.sum([image for image, _ in results], axis=0), meta)


def _splat_share(renderer_of, share, device, options, camera) -> tuple:
    """On a worker: the image of its share ``(i, n)``: coefficients ``i K / n .. (i + 1) K / n`` of each group
    in importance order (splatting is linear: the shares' images add up to the whole)."""
    others = {k: v for k, v in options.items() if k != "device_memory"}
    r = renderer_of(lambda wv, cap: SplatRenderer(wv, device=device, device_memory=cap, **others), device,
                    options.get("device_memory"), tuple(sorted(others.items())))
    i, n = share
    return _splat_range(r, camera, r.count * i // n, r.count * (i + 1) // n)


def splat_options(omega_s, sampling, coarse) -> tuple:
    """``(omega_s, sampling, coarse)`` of :class:`SplatRenderer` checked, the numbers as floats (a NumPy scalar is
    one; a bool is not): one line naming the argument, before a one-shot call's renderer is looked up by them."""
    omega_s = None if omega_s is None else check_omega_s(omega_s)
    check_sampling(sampling)
    if coarse is not None and not 0 < finite_number(coarse, "coarse") < 1:
        raise InputError(f"coarse={coarse!r} must be a tolerance between 0 and 1 (e.g. 1e-2), or None")
    return omega_s, sampling, (None if coarse is None else float(coarse))


def shared_renderer(wv: WaveletVolume, device, omega_s, sampling, coarse, device_memory=None) -> SplatRenderer:
    """The :class:`SplatRenderer` that one-shot calls on ``wv`` with these options share."""
    check_model(wv, "splatting")
    omega_s, sampling, coarse = splat_options(omega_s, sampling, coarse)
    cc = ComputeContext.get(device)
    cap = parse_cap(device_memory)
    return wv.shared(("splat", cc.info.id, omega_s, sampling, coarse, cap),
                     lambda: SplatRenderer(wv, device=cc, omega_s=omega_s, sampling=sampling, coarse=coarse,
                                           device_memory=cap))


def _bytes(table) -> int:
    """A host table's bytes, or a device buffer's (a perspective view's texel pool, :class:`ConeTables`)."""
    return table.nbytes if isinstance(table, np.ndarray) else table.size

