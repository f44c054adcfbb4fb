"""One splatted image being accumulated (docs/splatting.md §3): a :class:`~clwave.splat.renderer.SplatRenderer`'s
view begun (``begin``) splats coefficient ranges in importance order into the framebuffers of each channel group,
through the device stages (:mod:`clwave.splat.stages`), a pass of coefficients at a time.
"""

from __future__ import annotations

import time

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from ..device.kernels import zeros
from ..errors import DeviceMemoryError
from ..model.transform import band_code
from ..threads import drain, one_at_a_time
from .perspective import select_drops
from .stages import bin_chunks

#: the most coefficients one pass splats where they are all on the device, so that its per-splat buffers (32-40
#: bytes each, ``_work``) and tile lists stay small beside the coefficients (docs/splatting.md §6); a streamed chunk
#: is one pass
PASS_ROWS = 1 << 20


class Accumulator:
    """One image being accumulated: splat coefficient ranges in importance order into the
    framebuffers (layers) of each channel group, all layers in one pass."""

    def __init__(self, renderer, view, layers: list, tables: list, upto=None, record=None):
        self.r, self.view, self.layers, self.tables, self.upto = renderer, view, layers, tables, upto
        self.record = record or {}  # what meta records of the view: conebeam.view_record's
        self.lock = renderer.lock  # its passes use the renderer's buffers, a pass at a time
        # the coefficients and per-splat buffers its view was begun with (SplatRenderer._prepare): another view begun
        # between two of its passes (another thread's) may replace the renderer's with others of other shapes
        self.groups, self.chunk = renderer.groups, renderer.chunk
        self.resident, self.work = renderer._resident, renderer._work
        cc = renderer.cc
        pools = renderer.texel_pools(tables)
        self.device_tables = [{name: pool if name == "texels" else cc.upload(getattr(t, name)) for name in t.names}
                              for t, pool in zip(tables, pools)]
        self.fbs = [zeros(cc.queue, (t.pixels * 4,), np.float32) for t in tables]
        self.stats = dict(splats=0, pairs=0, pixel_updates=0, chunks=0, bin_seconds=0.0, accumulate_seconds=0.0,
                          upload_seconds=0.0, upsample_seconds=0.0)
        self.drop_share = [0.0] * len(tables)  # per group: the tolerance share dropped splats may take
        self.dropped = None  # what splat_dropping dropped

    @property
    def footprint_seconds(self) -> float:
        return sum(t.footprint_seconds for t in self.tables)

    @one_at_a_time
    def splat(self, first: int, count: int):
        """Add coefficients ``first .. first + count`` (importance order) of every group."""
        drain(self.passes(first, count))

    def passes(self, first: int, count: int, own=False):
        """:meth:`splat` as a generator yielding between its stages: after each pass's binning, and between the
        bands of its accumulation (a viewer's saved image takes turns with the tabs' frames there, docs/viewer.md
        §5); the caller holds the renderer's lock for each stage.  ``own``: the passes' tile lists and streamed
        chunks are in buffers of this image's own, which another image splatted by the renderer between two stages
        does not write over (the same passes, so the same image bit for bit)."""
        if self.upto is not None and first + count > self.upto:
            raise ValueError(f"this image was begun for the first {self.upto} coefficients only")
        for gi, g in enumerate(self.groups):
            n = max(0, min(count, g["count"] - first))
            for coef, values, offset, m in self._chunks(gi, first, n, own):
                yield from self._splat_group(gi, coef, values, offset, m, own=own)
            self.stats["splats"] += n

    def _chunks(self, gi, first, n, own=False):
        """``(coef, values, offset, count)`` on the device for coefficients ``first .. first + n`` of group
        ``gi``, a pass each: where they are all on the device, that range of them, :data:`PASS_ROWS` at a time;
        else chunk after chunk, each copied in turn into the one chunk buffer (docs/splatting.md §6; ``own``: a
        buffer of this image's, as :meth:`passes`)."""
        r = self.r
        if self.chunk is None:
            for lo in range(first, first + n, PASS_ROWS):
                yield (*self.resident[gi], lo, min(PASS_ROWS, first + n - lo))
            return
        coef, values = self.work["coef"], self.work["values"]
        if own:
            coef, values = cla.empty_like(coef), cla.empty_like(values)
        table = self.groups[gi]["table"]
        for lo in range(first, first + n, self.chunk):
            m = min(self.chunk, first + n - lo)
            start = time.perf_counter()
            for device, host in zip((coef, values), (table.coef[lo:lo + m], table.packed[lo:lo + m])):
                cl.enqueue_copy(r.cc.queue, device.data, host)  # blocking
            self.stats["upload_seconds"] += time.perf_counter() - start
            self.stats["chunks"] += 1
            yield coef, values, 0, m

    @one_at_a_time
    def splat_dropping(self):
        """Add every coefficient of a perspective view, less the wavelet splats of the image's framebuffer whose
        bounds, summed over any pixel, stay within :attr:`drop_share` of the image maximum (docs/splatting.md §8
        "Dropped splats"): first every other splat, whose image's maximum sets the budget, then the wavelet splats
        kept; should the finished image's maximum not cover the dropped splats' bound, the dearest of them are drawn
        too, until it does."""
        r, obliquity = self.r, float(self.view.obliquity().max())
        plans = []
        for gi, g in enumerate(self.groups):
            n = g["count"]
            bbox, stex = self._projection(gi)
            wavelet = np.flatnonzero((band_code(g["table"].band) != 0) & (bbox[:, 2] >= bbox[:, 0]))
            wavelet = wavelet[self.tables[gi].tex_layer[stex[wavelet], 0] == 0]  # drawn at the image's pixels
            bound = self.tables[gi].splat_bounds(self.view, bbox[wavelet], stex[wavelet], g["table"].values[wavelet])
            plans.append((wavelet, bbox[wavelet], bound))
            self._draw(gi, wavelet, False, projected=n <= PASS_ROWS)  # one pass: the work arrays hold its projection
            self.stats["splats"] += n
        drops = [None] * len(plans)  # per group: (the candidates left undrawn, the largest sum of their bounds)
        while True:  # E L <= share (top - E L): the dropped splats' error within share of the finished image's maximum
            image, done = self.image(), True
            tops = [np.abs(image[..., list(g.channels)]).reshape(-1, len(g.channels)).max(axis=0)
                    for g in r.wv.groups]  # per group and channel
            for gi, (wavelet, bbox, bound) in enumerate(plans):
                chans, share, top = list(r.wv.groups[gi].channels), self.drop_share[gi], tops[gi]
                error = None if drops[gi] is None else drops[gi][1] * obliquity  # bound of the dropped splats' error
                if error is not None and np.all(error <= share * (top - error)):
                    continue
                done = False
                candidates = np.ones(len(wavelet), bool) if drops[gi] is None else drops[gi][0]
                drop, most = np.zeros(len(wavelet), bool), np.zeros(len(chans))
                if top.min() > 0 and candidates.any():
                    sub, most = select_drops(bbox[candidates], bound[candidates], self.view.size,
                                             share * top / (obliquity * (1.0 + share)))
                    drop[np.flatnonzero(candidates)[sub]] = True
                self._draw(gi, wavelet[candidates & ~drop], True)
                drops[gi] = (drop, most)
            if done:
                break
        self.dropped = dict(splats=0, pixel_updates=0, bound=0.0)
        for (_, bbox, _), (drop, most), top in zip(plans, drops, tops):
            box = bbox[drop]
            self.dropped["splats"] += int(drop.sum())
            self.dropped["pixel_updates"] += int(np.sum((box[:, 2] - box[:, 0] + 1).astype(np.int64)
                                                        * (box[:, 3] - box[:, 1] + 1)))
            if drop.any():
                self.dropped["bound"] = max(self.dropped["bound"], float(np.max(most * obliquity / top)))

    def _projection(self, gi) -> tuple:
        """The pixel box and texture of each splat of group ``gi`` (all on the device), a pass at a time."""
        r, w, n = self.r, self.work, self.groups[gi]["count"]
        bbox, stex = np.empty((n, 4), np.int32), np.empty(n, np.int32)
        for coef, _, lo, m in self._chunks(gi, 0, n):
            r.stage(self.groups[gi]["channels"], True).project(m, lo, coef, self.device_tables[gi], w["centre"],
                                                            w["bbox"], w["stex"], w["counts"])
            bbox[lo:lo + m], stex[lo:lo + m] = w["bbox"][:m].get(), w["stex"][:m].get()
        return bbox, stex

    def _draw(self, gi, where, value: bool, projected=False):
        """Splat group ``gi``'s coefficients at indices ``where`` (``value``) or all but those (not ``value``), a
        pass at a time; ``projected`` as for :meth:`_splat_group` (one pass)."""
        n = self.groups[gi]["count"]
        keep = np.full(n, not value)
        keep[where] = value
        for coef, values, lo, m in self._chunks(gi, 0, n):
            if keep[lo:lo + m].any():
                drain(self._splat_group(gi, coef, values, lo, m, keep=keep[lo:lo + m], projected=projected))

    def _splat_group(self, gi, coef, values, first, n, keep=None, projected=False, own=False):
        """Splat coefficients ``first .. first + n`` of the device arrays ``coef``, ``values`` of group ``gi``,
        yielding between the stages of :meth:`passes` (``own`` as there); ``keep``: a mask of those to splat (the
        others' boxes are emptied after projection); ``projected``: the work arrays hold these coefficients'
        projection, unmasked (``splat_dropping``'s first draw of a group).  The per-splat work arrays are the
        renderer's, used within the binning's stage only."""
        r, q = self.r, self.r.cc.queue
        g, t, tables, w = self.groups[gi], self.device_tables[gi], self.tables[gi], self.work
        st = r.stage(g["channels"], self.view.perspective)
        start = time.perf_counter()
        centre, bbox, stex, counts = w["centre"], w["bbox"], w["stex"], w["counts"]  # the first n are this pass's
        if not projected:
            st.project(n, first, coef, t, centre, bbox, stex, counts)
        if keep is not None:
            r.mask_splats(bbox, counts, cla.to_device(q, keep.view(np.uint8)), range=slice(0, n), queue=q)
        total = int(cla.sum(counts[:n], dtype=np.uint64).get())
        budget = st.pair_budget(r.budget)
        if total > budget and n > 1:  # too many tile pairs for the device: split the chunk
            half = n // 2
            self.stats["bin_seconds"] += time.perf_counter() - start
            yield from self._splat_group(gi, coef, values, first, half, None if keep is None else keep[:half], own=own)
            yield from self._splat_group(gi, coef, values, first + half, n - half,
                                         None if keep is None else keep[half:], own=own)
            return
        if total > budget:
            raise DeviceMemoryError(f"one splat needs {total * st.record_bytes} bytes of tile lists, more "
                                    f"than {r.cc.info.name} can hold; render a smaller image")
        tiles = tables.tiles
        ranges = zeros(q, (tiles, 2), np.uint32, allocator=r.scratch)
        nbytes = max(total, 1) * st.record_bytes
        records = cl.Buffer(r.cc.ctx, cl.mem_flags.READ_WRITE, nbytes) if own else r.tile_lists(nbytes)
        if total:
            textures = max(tables.layer_textures)
            chunks = bin_chunks(n, tiles * textures, r.cc.info, r.budget)
            runs = tiles * textures
            # chunk-major counts (each chunk's together, cached by its core), scanned run-major,
            # then back to chunk-major as each chunk's write cursors
            table = cla.empty(q, (chunks * runs,), np.uint32, allocator=r.scratch)
            by_run, starts = cla.empty_like(table), cla.empty_like(table)
            splats = (n, chunks, tiles, textures, first, bbox, centre, stex, values, t)
            st.count(*splats, table, pairs=total)
            st.transpose(chunks, runs, table, by_run)
            st.scan(by_run, starts)
            st.ranges(tiles, textures, chunks, total, starts, ranges)
            st.transpose(runs, chunks, starts, table)
            st.place(*splats, table, records, pairs=total)
        q.finish()
        self.stats["bin_seconds"] += time.perf_counter() - start
        self.stats["pairs"] += total
        self.stats["pixel_updates"] += int(r.pixel_updates(bbox, range=slice(0, n), queue=q).get())
        yield  # the accumulation needs the records, ranges, tables and framebuffers only, none of them the work arrays
        mid = time.perf_counter()
        for _ in st.accumulating(tiles, len(tables.layers), t, ranges, records, self.fbs[gi]):
            self.stats["accumulate_seconds"] += time.perf_counter() - mid
            yield
            mid = time.perf_counter()
        q.finish()
        self.stats["accumulate_seconds"] += time.perf_counter() - mid

    def meta(self, seconds: float) -> dict:
        """What :class:`~clwave.RenderResult` reports of this image after ``seconds``."""
        r, tables = self.r, self.tables
        return dict(method="splat", device=r.cc.describe(), coefficients=self.stats["splats"],
                    coefficients_total=self.groups[0]["count"] if self.groups else 0, tile_pairs=self.stats["pairs"],
                    pixel_updates=self.stats["pixel_updates"],
                    texture_sampling=sorted({s for t in tables for s in t.samplings}),
                    omega_s=tables[0].omega_s if tables else None,
                    coarse=r.coarse, framebuffers=[layer.factor for layer in self.layers],
                    device_budget=r.budget.total, chunk_coefficients=self.chunk,
                    coefficient_chunks=self.stats["chunks"],
                    seconds=dict(total=seconds, footprints=self.footprint_seconds,
                                 binning=self.stats["bin_seconds"], accumulation=self.stats["accumulate_seconds"],
                                 upload=self.stats["upload_seconds"], upsampling=self.stats["upsample_seconds"],
                                 compile=r.compile_seconds),
                    **self.record, **({} if self.dropped is None else dict(dropped=self.dropped)))

    def image(self) -> np.ndarray:
        """The image so far as (H, W, C) float32: the framebuffers summed at the image's pixels."""
        H, W = self.view.size
        start = time.perf_counter()
        out = np.zeros((H, W, self.r.wv.channels), np.float32)
        for gi, g in enumerate(self.r.wv.groups):
            fb = self.fbs[gi].get().reshape(-1, 4)[:, : len(g.channels)]
            out[..., list(g.channels)] = sum(layer.image(fb[first: first + w * h]) for layer, (w, h, _, first), drawn
                                             in zip(self.layers, self.tables[gi].layers, self.tables[gi].layer_textures)
                                             if drawn)  # a layer may draw nothing of this group
        if len(self.layers) > 1:
            self.stats["upsample_seconds"] += time.perf_counter() - start
        if self.view.perspective:  # the path length per unit depth of each pixel's ray (docs/splatting.md §8)
            out *= self.view.obliquity().astype(np.float32)[..., None]
        return out
