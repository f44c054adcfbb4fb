"""A ``.clw`` file in the viewer, opened by its prefix first (docs/viewer.md §2), and per-tab pacing: served before
the whole file is read, a refinement under way kept through the swap, the final frame clwave.splat of the whole
model."""

import asyncio
import contextlib
import json
import threading

import aiohttp
import numpy as np
import pytest

import clwave
from clwave.model.ranking import by_importance, ranked_table
from clwave.model.wavelet import ChannelGroup
from clwave.splat.ranked import ranked_groups
from clwave.splat.renderer import SplatRenderer
from clwave.io import clw as clw_io
from clwave.io import summary
from clwave.view import frames as view_frames
from clwave.view import prefix as view_prefix
from clwave.view import view
from clwave.view.frames import XraySource
from clwave.view.prefix import PrefixFirst, prefix_first
from clwave.view.protocol import model_id, unpack_frame

PASS = 4096  # coefficients a still pass adds in the test of a swap under way
BASE = dict(type="view", azimuth=30.0, elevation=20.0, zoom=1.0, mode="xray", detail=1.0, window=None, moving=False,
            background=0.0, shading=True)
SIZE = (40, 48)


@pytest.fixture(scope="module")
def clw(tmp_path_factory):
    """Hydrogen 40^3 RGBA, 20 % kept: 12,800 coefficients in the file."""
    path = tmp_path_factory.mktemp("view") / "hydrogen.clw"
    rgba = clwave.TransferFunction.preset("hydrogen").classify(clwave.phantom("hydrogen", n=40))
    clwave.WaveletVolume.from_volume(rgba, levels=2).threshold(keep=0.2).save(path)
    return path


async def receive(ws):
    """The next message: ``("frame", figures)`` or ``(type, message)``."""
    msg = await ws.receive(timeout=60)
    if msg.type == aiohttp.WSMsgType.BINARY:
        figures, data = unpack_frame(msg.data)
        return "frame", dict(figures, data=data)
    assert msg.type == aiohttp.WSMsgType.TEXT, msg
    message = json.loads(msg.data)
    return message["type"], message


def test_a_clw_file_is_served_from_its_prefix_then_refined_to_the_whole_models_splat(clw, monkeypatch):
    """The server answers from the file's 2,048 most important coefficients while the rest is not read (held by a
    gate); no frame of the prefix is final; once read, the page hears the whole model and the still view is
    rendered again, from no fewer coefficients, to clwave.splat of the whole file within one grey level."""
    monkeypatch.setattr(view_prefix, "PREFIX", 2048)
    gate, whole = threading.Event(), PrefixFirst.whole
    monkeypatch.setattr(PrefixFirst, "whole", lambda self, **k: gate.wait(60) and whole(self, **k))
    model = clwave.WaveletVolume.open(clw)

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(v.url.replace("/?", "/ws?"))
            kind, hello = await receive(ws)
            await ws.send_str(json.dumps(dict(BASE, seq=1)))
            before = []
            while not before or (before[-1]["mime"], before[-1]["coefficients"]) != ("image/png", 2048):
                kind, message = await receive(ws)
                before.append(message)
            assert not gate.is_set()  # all of that before the rest of the file was read
            gate.set()
            after = []
            while not after or not after[-1]["final"]:
                kind, message = await receive(ws)
                if kind == "model":
                    model_message = message
                else:
                    after.append(message)
            return hello, before, model_message, after

    with view(clw, size=SIZE) as v:
        hello, before, model_message, after = asyncio.run(go(v))
        assert v.server.wv.kept == model.kept
    assert hello["model"]["reading"] and hello["model"]["coefficients"] == 2048
    assert hello["model_id"] == model_id(model)  # the page's kept view is the file's, prefix or whole (viewer.md §4)
    assert all(f["prefix"] and not f["final"] for f in before)
    assert not model_message["model"]["reading"] and model_message["model"]["coefficients"] == model.kept
    assert [f["seq"] for f in after] == [1] * len(after) and after[0]["coefficients"] >= 2048
    final = after[-1]
    assert final["coefficients"] == model.kept and final["mime"] == "image/png" and not final["prefix"]
    camera = clwave.Camera(30.0, 20.0, SIZE, extent=final["extent"])
    expect = clwave.splat(model, camera).to_uint8(tuple(final["window"]))
    got = decode(final["data"])
    assert expect.std() > 10 and np.abs(got.astype(int) - expect).max() <= 1


def test_a_failed_reading_of_the_rest_is_logged_and_told_and_the_prefix_goes_on(clw, monkeypatch, caplog):
    """Reading the rest failing (a file damaged past its prefix): one logged line; the tab hears the model is no
    longer being read, and the line on its status line (an error of no view, so that a view moved to meanwhile shows
    it); the prefix is the model served from then on, its still views ending final."""
    monkeypatch.setattr(view_prefix, "PREFIX", 2048)
    monkeypatch.setattr(PrefixFirst, "whole", lambda self, **k: (_ for _ in ()).throw(
        clwave.FileFormatError("damaged")))

    async def last_frame(ws, seq):  # the still view's last frame (all of the prefix); other messages kept
        heard = {}
        while True:
            kind, message = await receive(ws)
            if kind != "frame":
                heard[kind] = message
            elif (message["seq"], message["mime"], message["coefficients"]) == (seq, "image/png", 2048):
                return message, heard

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(v.url.replace("/?", "/ws?"))
            await receive(ws)
            await ws.send_str(json.dumps(dict(BASE, seq=1, azimuth=31.0)))
            await last_frame(ws, 1)
            while v.server._reader.ident is None:  # started just after the first frame is sent
                await asyncio.sleep(0.01)
            v.server._reader.join(30)
            told = {}
            while not {"model", "error"} <= set(told):
                kind, message = await receive(ws)
                told[kind] = message
            await ws.send_str(json.dumps(dict(BASE, seq=2, azimuth=32.0)))
            frames = []  # the view's frames to its final one (a drag frame of all 2,048 first)
            while not (frames and frames[-1][0]["final"]):
                frames.append(await asyncio.wait_for(last_frame(ws, 2), 60))
            return told, frames, frames[-1][1]

    with view(clw, size=SIZE) as v:
        told, frames, heard = asyncio.run(go(v))
    assert not told["model"]["model"]["reading"] and told["model"]["model"]["failure"] == "damaged"
    assert told["model"]["model"]["coefficients"] == 2048
    assert "seq" not in told["error"] and told["error"]["message"].endswith("views failed (they go on with what "
                                                                            "they have): damaged")
    assert all(not f["prefix"] for f, _ in frames) and not heard  # the prefix is the model now: its views end final
    assert [r.getMessage() for r in caplog.records if "failed" in r.getMessage()] == [
        "making the whole model for xray views failed: damaged"]


def test_a_ranking_that_does_not_extend_the_prefix_is_logged_and_the_prefix_goes_on(clw, monkeypatch, caplog):
    """The whole model ranked by its own importance (not the prefix's first): the renderer refuses it, one logged
    line, and the prefix goes on being served, as the model from then on (the failure in the model's figures)."""
    monkeypatch.setattr(view_prefix, "PREFIX", 2048)
    monkeypatch.setattr(view_prefix, "prefix_first",
                        lambda whole, prefix, rows=None: [by_importance(whole.importance(g)) for g in whole.groups])

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(v.url.replace("/?", "/ws?"))
            await receive(ws)
            await ws.send_str(json.dumps(dict(BASE, seq=1)))
            kind, message = await receive(ws)
            while (message["mime"], message["coefficients"]) != ("image/png", 2048):
                kind, message = await receive(ws)
            while v.server._reader.ident is None:
                await asyncio.sleep(0.01)
            v.server._reader.join(30)
            v.server.pool.submit(lambda: None).result(30)  # the swap's turn on the render thread has come

    with view(clw, size=SIZE) as v:
        asyncio.run(go(v))
        assert v.server.sources["xray"].complete and v.server.sources["xray"].r.count == 2048
        assert v.server.model()["failure"] == "internal error (ValueError); see the server's log"
    assert any("failed: the groups do not begin" in r.getMessage() for r in caplog.records)


def test_a_refinement_under_way_keeps_its_model_through_the_swap(clw):
    """Swapping the whole model in between two stages of a still view: that view's frames go on to the prefix's
    last coefficient, none final, the last the prefix's own image; the same view again refines to the whole
    model."""
    prefix = clwave.WaveletVolume.open(clw, keep=3 * PASS / 40**3)
    model = clwave.WaveletVolume.open(clw)
    xray = XraySource(prefix, SIZE, SplatRenderer(prefix), complete=False)
    xray.rate = view_frames.STILL_SECONDS / PASS  # a pass of 4096 coefficients a frame
    state, pace = view_frames.ViewState(1, 50.0, 10.0, 1.0, "xray", 1.0, None, False, 0.0, True), xray.pacing()
    pace.dragged = (50.0, 10.0, 1.0)  # the page has this view's drag frame: still passes only
    under_way = xray.frames(state, pace)
    first = next(under_way)
    xray.swap(model, ranked_groups(model, prefix_first(model, prefix)))
    rest = [first] + list(under_way)
    counts = [f.figures["coefficients"] for f in rest]
    assert len(rest) > 1 and counts[-1] == 3 * PASS and not any(f.figures["final"] for f in rest)
    again = list(xray.frames(state, pace))
    assert again[0].figures["coefficients"] >= 3 * PASS and again[-1].figures["final"]
    assert again[-1].figures["coefficients"] == model.kept
    camera = clwave.Camera(50.0, 10.0, SIZE, extent=rest[-1].figures["extent"])
    assert np.array_equal(decode(rest[-1].data), clwave.splat(prefix, camera).to_uint8(xray.auto_window))


def test_ranking_is_the_numpy_oracles_order_and_bands(clw):
    """``WaveletVolume.ranked`` (keys sorted, bands by arithmetic) against a plain NumPy oracle: a lexsort by
    decreasing importance then position, and each band's ``np.unravel_index``; on the file's model and on one whose
    values are all alike (importance ties everywhere within a band, so the positions decide)."""
    model = clwave.WaveletVolume.open(clw)
    g = model.groups[0]
    alike = clwave.WaveletVolume(model.shape, model.spacing, model.origin, model.levels, [ChannelGroup(
        g.wavelet, g.channels, g.bands, g.positions, np.ones_like(g.values))], model.channels)
    for wv in (model, alike):
        g = wv.groups[0]
        positions, importance = g.all_positions(), wv.importance(g)
        order = np.lexsort((positions, -importance))
        starts = np.array([b.start for b in g.bands])
        band = np.searchsorted(starts, positions[order], side="right") - 1
        index = np.array([np.unravel_index(p - g.bands[b].start, g.bands[b].shape)
                          for p, b in zip(positions[order], band)])
        table = wv.ranked(0)
        assert wv is model or len(np.unique(importance)) < len(g.bands)  # ties: one importance a band
        assert np.array_equal(table.index, index) and np.array_equal(table.values, g.values[:, order].T)
        assert np.array_equal(table.band, [g.bands[b].level * 8 + g.bands[b].code for b in band])
        assert np.array_equal(table.importance, importance[order])


def head(wv, count):
    """The model of the ``count`` first coefficients of ``wv.ranked()`` (of each group)."""
    groups = []
    for g in wv.groups:
        rows = np.sort(by_importance(wv.importance(g))[:count])
        groups.append(ChannelGroup(g.wavelet, g.channels, g.bands, g.all_positions()[rows], g.values[:, rows]))
    return clwave.WaveletVolume(wv.shape, wv.spacing, wv.origin, wv.levels, groups, wv.channels)


CAMERAS = [clwave.Camera(30.0, 20.0, SIZE), clwave.Camera(-70.0, 55.0, (33, 20))]


def test_a_renderer_extended_to_a_model_whose_ranking_it_heads_is_that_models_renderer(clw):
    """``SplatRenderer.extend``: a renderer of the 3,000 most important coefficients, extended to the whole model
    (its ranking begins with theirs), is the whole model's fresh renderer bit for bit: tables, energy, images and
    counts, all on the device or streamed in chunks; a view begun before the extension ends as the head's view (the
    same passes) does."""
    model = clwave.WaveletVolume.open(clw)
    part = head(model, 3000)
    tables = prefix_first(model, part)
    for g, order in zip(model.groups, tables):
        assert np.array_equal(order, by_importance(model.importance(g)))
    for cap in (None, "2MiB"):  # 2 MiB: the head on the device, the whole streamed
        r = SplatRenderer(part, device_memory=cap)
        under_way = r.begin(CAMERAS[0])
        under_way.splat(0, 1000)
        r.extend(model, ranked_groups(model, tables))
        under_way.splat(1000, 2000)
        alone = SplatRenderer(part, device_memory=cap).begin(CAMERAS[0])
        alone.splat(0, 1000)
        alone.splat(1000, 2000)
        assert np.array_equal(under_way.image(), alone.image())
        fresh = SplatRenderer(model, device_memory=cap)
        assert r.count == fresh.count == model.kept and np.array_equal(r.energy, fresh.energy)
        for camera in CAMERAS:
            got, want = r.render(camera), fresh.render(camera)
            assert want.image.std() > 0 and np.array_equal(got.image, want.image)
            for key in ("coefficients", "tile_pairs", "pixel_updates", "chunk_coefficients", "coefficient_chunks"):
                assert got.meta[key] == want.meta[key], key
        assert (cap is None) == (fresh.render(CAMERAS[0]).meta["chunk_coefficients"] is None)


def test_a_files_prefix_extended_to_the_whole_file_is_its_splat_to_float_rounding(clw, monkeypatch):
    """A file's prefix (``open(keep=)``: the approximation first) extended to the whole file: its ranking is the
    prefix's, then the rest's, each by importance, so a view of every coefficient is the same float32 sum as the
    fresh renderer's in another order; each pixel then differs by at most 2 gamma_(m-1) sum |t| (m terms t, any
    order, gamma_k = k u / (1 - k u), u = 2^-24: Higham, Accuracy and Stability of Numerical Algorithms, §4.2),
    with sum |t| rendered from |c| and |footprint texels| and m at most the coefficients.  Counts alike, energy to
    float64 rounding of its sum."""
    model = clwave.WaveletVolume.open(clw)
    part = clwave.WaveletVolume.open(clw, keep=2048 / 40**3)
    tables = prefix_first(model, part)
    for gi, (g, order) in enumerate(zip(model.groups, tables)):
        table = ranked_table(g, order, importance=model.importance(g))
        assert np.array_equal(table.index[:2048], part.ranked(gi).index)
        assert np.all(np.diff(table.importance[:2048]) <= 0) and np.all(np.diff(table.importance[2048:]) <= 0)
        assert table.importance[2048:].max() > table.importance[:2048].min()  # not the whole's ranking
    r = SplatRenderer(part)
    r.render(CAMERAS[0])
    r.extend(model, ranked_groups(model, tables))
    fresh = SplatRenderer(model)
    m = model.kept
    gamma = (m - 1) * 2.0**-24 / (1 - (m - 1) * 2.0**-24)
    assert np.isclose(r.energy[-1], fresh.energy[-1], rtol=2 * m * 2.0**-53, atol=0)
    magnitude = clwave.WaveletVolume(model.shape, model.spacing, model.origin, model.levels, [
        ChannelGroup(g.wavelet, g.channels, g.bands, g.positions, np.abs(g.values)) for g in model.groups],
        model.channels)
    for camera in CAMERAS:
        got, want = r.render(camera), fresh.render(camera)
        with monkeypatch.context() as patch:
            patch.setattr(SplatRenderer, "texel_pools", lambda self, tables: [self.cc.upload(np.abs(t.texels))
                                                                              for t in tables])
            bound = SplatRenderer(magnitude).render(camera).image.astype(np.float64) * (1 + gamma)
        assert want.image.std() > 0
        assert np.all(np.abs(got.image.astype(np.float64) - want.image) <= 2 * gamma * bound)
        for key in ("coefficients", "tile_pairs", "pixel_updates"):
            assert got.meta[key] == want.meta[key], key


def test_a_prefix_not_part_of_the_whole_is_refused(clw):
    """A prefix that is not a part of the whole model read after it (the file replaced meanwhile): one line; a
    renderer is not extended by a ranking that does not begin with its own (a file's prefix by the whole's)."""
    model = clwave.WaveletVolume.open(clw)
    other = head(model, 100)
    other.groups[0].values[0, 0] += 1.0
    with pytest.raises(clwave.FileFormatError, match="not a part of the whole file"):
        prefix_first(model, other)
    moved, fewer = head(model, 100), head(model, 100)  # the same coefficients in another frame; a group short
    moved.spacing = tuple(2.0 * s for s in moved.spacing)
    fewer.groups = fewer.groups[:-1]
    for part in (moved, fewer):
        with pytest.raises(clwave.FileFormatError, match="not a part of the whole file"):
            prefix_first(model, part)
    with pytest.raises(ValueError, match="do not begin with"):
        SplatRenderer(clwave.WaveletVolume.open(clw, keep=2048 / 40**3)).extend(model, ranked_groups(model))


def test_a_replaced_file_gives_the_shaded_views_no_model(clw):
    """The reading thread checks the prefix against the whole file before it hands the whole to the shaded views:
    a file replaced meanwhile fails both modes alike, so no page shows two volumes."""
    from concurrent.futures import Future
    from types import SimpleNamespace

    from clwave.view.server import ViewServer

    model = clwave.WaveletVolume.open(clw)
    other = head(model, 100)
    other.groups[0].values[0, 0] += 1.0
    told = []
    state = SimpleNamespace(whole=Future(), upgraded=lambda mode, exc=None: told.append((mode, exc)),
                            coarse_first=False, _stop=threading.Event(), _in_file=threading.Event(),
                            logged=lambda call, *args: call(*args))
    ViewServer._read_whole(state, SimpleNamespace(whole=lambda **k: model, prefix=other, path=clw))
    with pytest.raises(clwave.FileFormatError, match="not a part of the whole file"):
        state.whole.result(timeout=0)
    assert len(told) == 1 and told[0][0] == "xray" and isinstance(told[0][1], clwave.FileFormatError)


@pytest.mark.parametrize("prefix", [None, 2048])
def test_the_shaded_mode_of_a_clw_file_ends_at_the_ray_trace_of_the_whole_file(clw, monkeypatch, prefix):
    """A .clw file's shaded views come from a staged tracer: coarse-stage frames (not final) while the whole file is
    set up, and a still view ends at clwave.raytrace of the whole model within one grey level.  The full stage takes
    the model the viewer holds (the prefix, all of this file) or reads for its X-ray views (a prefix of 2,048): the
    whole file is read once at most (instrumented)."""
    if prefix is not None:
        monkeypatch.setattr(view_prefix, "PREFIX", prefix)
    reads, open_ = [], clwave.WaveletVolume.open.__func__
    monkeypatch.setattr(clwave.WaveletVolume, "open", classmethod(
        lambda cls, path, keep=None, **k: reads.append((keep, k.get("approximation", False))) or
        open_(cls, path, keep, **k)))

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(v.url.replace("/?", "/ws?"))
            await ws.receive_json()
            await ws.send_str(json.dumps(dict(BASE, seq=1, mode="shaded", azimuth=10.0)))
            frames = []
            while not frames or not frames[-1]["final"]:
                kind, message = await receive(ws)
                if kind == "frame":
                    frames.append(message)
            return frames

    with view(clw, size=32, tolerance=2e-2) as v:
        frames = asyncio.run(go(v))
    waiting = [f["waiting"] for f in frames if f.get("waiting")]  # the page's status line (frames.js waitingWords)
    assert waiting and all(not f["final"] for f in frames if f.get("waiting")) and frames[-1]["detail"] == 0
    if prefix is None:  # the file served whole: nothing read, the wait is the whole tracer's set-up (trial24 row 5)
        assert set(waiting) == {"set-up"}
    # the prefix, the coarse stage's approximation, and (a prefix of 2,048) the rest read once, for both modes
    assert reads == [(1.0, False), (None, True)] if prefix is None else \
        reads == [(2048 / 40 ** 3, False), (None, True), (None, False)]
    expect = clwave.raytrace(clwave.WaveletVolume.open(clw), clwave.Camera(10.0, 20.0, 32, extent=frames[-1]["extent"]),
                             tolerance=2e-2).to_uint8(background=(0.0, 0.0, 0.0))
    assert expect.std() > 5 and np.abs(decode(frames[-1]["data"]).astype(int) - expect).max() <= 1


def test_a_shaded_view_asked_for_while_the_rest_is_read_does_not_wait_for_it(clw, monkeypatch):
    """h5py serialises its calls, and the rest's reads take seconds each at 1024^3: the reading thread reads what the
    shaded views' coarse stage reads of the file before the rest, and the coarse stage takes it, so a still shaded
    view asked for while the rest is read has its first (coarse) frame meanwhile (docs/viewer.md §2).  Instrumented:
    every opening of the file takes one lock, as h5py's calls do, which the rest's reading holds until that frame has
    come; an opening that finds it held is recorded (and lets the rest go on, so that a failure is quick)."""
    monkeypatch.setattr(view_prefix, "PREFIX", 2048)
    files, reading, release, waited = threading.RLock(), threading.Event(), threading.Event(), []
    open_clw, open_ = clw_io.open_clw, clwave.WaveletVolume.open.__func__

    @contextlib.contextmanager
    def locked(path):
        held = files.acquire(blocking=False)
        if not held:  # the rest's reading holds it: this read would wait for all of it
            waited.append(threading.current_thread().name)
            release.set()
            held = files.acquire(timeout=10)  # not forever: a thread the rest's reading waits for may be here
        try:
            with open_clw(path) as opened:
                yield opened
        finally:
            if held:
                files.release()

    def open_model(cls, path, keep=None, **k):
        if keep is not None or k.get("approximation"):
            return open_(cls, path, keep, **k)
        with files:  # the rest's reading
            reading.set()
            release.wait(60)
            return open_(cls, path, keep, **k)

    for module in (clw_io, summary):
        monkeypatch.setattr(module, "open_clw", locked)
    monkeypatch.setattr(clwave.WaveletVolume, "open", classmethod(open_model))

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(v.url.replace("/?", "/ws?"))
            await ws.receive_json()
            await ws.send_str(json.dumps(dict(BASE, seq=1)))  # an X-ray view: its first frame starts the reading
            while (await receive(ws))[0] != "frame":
                pass
            assert await asyncio.to_thread(reading.wait, 30)
            await ws.send_str(json.dumps(dict(BASE, seq=2, mode="shaded")))
            while True:
                kind, message = await receive(ws)
                if kind == "frame" and message["seq"] == 2:
                    release.set()
                    return message

    frame = None
    try:
        with view(clw, size=32, tolerance=2e-2) as v:
            frame = asyncio.run(asyncio.wait_for(go(v), 60))  # the server's pings keep each receive waiting
    except TimeoutError:
        pass
    finally:
        release.set()
    assert not waited, f"openings of the file that waited behind the rest's reading: {waited}"
    assert frame is not None and frame["waiting"] == "reading" and not frame["final"]


def test_tabs_pace_their_drag_frames_apart(clw, monkeypatch):
    """One tab's fast drags grow its own drag prefix only: another tab's first drag frame has a fresh tab's."""
    monkeypatch.setattr(view_frames, "DRAG_SECONDS", 60.0)  # every drag frame is fast: each doubles the prefix

    async def drag(ws, seqs):
        counts = []
        for seq in seqs:
            await ws.send_str(json.dumps(dict(BASE, seq=seq, azimuth=30.0 + seq, moving=True)))
            kind, message = await receive(ws)
            while kind != "frame":
                kind, message = await receive(ws)
            counts.append(message["coefficients"])
        return counts

    async def go(v):
        async with aiohttp.ClientSession() as s:
            a, b = [await s.ws_connect(v.url.replace("/?", "/ws?")) for _ in range(2)]
            await a.receive_json(), await b.receive_json()
            return await drag(a, range(1, 5)), await drag(b, [1])

    model = clwave.WaveletVolume.open(clw)
    with view(model, size=SIZE) as v:
        fresh = v.server.sources["xray"].pacing().drag_count
        first, other = asyncio.run(go(v))
    assert first[0] == other[0] == fresh and first[-1] > 2 * fresh


def decode(data):
    import io

    import imageio.v3 as iio
    return iio.imread(io.BytesIO(data))
