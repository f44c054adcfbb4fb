"""The viewer's threads (docs/viewer.md §1, §2): a stop (Ctrl-C, ``Viewer.close()``) stops reading a file's rest and
gives up the shaded views' set-up, so that the process ends; a staged tracer's render races no other thread; a tab
closed while the ray tracer is prepared leaves no task behind; a file damaged or replaced while served."""

import asyncio
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import aiohttp
import h5py
import numpy as np
import pytest

import clwave
from clwave.raytrace.staged import StagedTracer
from clwave.view import prefix as view_prefix
from clwave.view import view
from clwave.view.prefix import PrefixFirst
import test_view_prefix
from test_hardening import sigint_default

BASE = dict(type="view", azimuth=30.0, elevation=20.0, zoom=1.0, mode="xray", detail=1.0, window=None, moving=False,
            background=0.0, shading=True)
clw = test_view_prefix.clw  # the fixture: hydrogen 40^3 RGBA, 12,800 coefficients in the file
THREADS = ("clwave-view-read", "clwave-staged-setup", "clwave-view-full-stage")


def alive(names=THREADS) -> list:
    return sorted(t.name for t in threading.enumerate() if t.name in names)


def seconds_to_end(p, limit, what) -> float:
    """Seconds until the process ``p`` ends; the test fails where it has not ended within ``limit``."""
    start = time.perf_counter()
    try:
        p.wait(limit)
    except subprocess.TimeoutExpired:
        pytest.fail(f"{what} did not end within {limit} s")
    return time.perf_counter() - start


def test_ctrl_c_while_the_rest_is_read_ends_the_process(clw, tmp_path):
    """``clwave view FILE.clw`` interrupted while the rest is read: the reading holds h5py's lock for 3 s (as a long
    read does); the server stops the reader and waits for it, so the process ends (a daemon reader stopped by the
    interpreter inside the read would keep the lock, and the exit would wait for it for ever)."""
    script = tmp_path / "slow_view.py"
    script.write_text(textwrap.dedent("""
        import sys, time
        import h5py
        from clwave.cli import main
        from clwave.view import prefix, server

        prefix.PREFIX, server.READ_AFTER = 2048, 0.1
        whole = prefix.PrefixFirst.whole
        def slow(self, *a, **k):
            print("reading the rest", flush=True)
            with h5py._objects.phil:
                time.sleep(3.0)
            return whole(self, *a, **k)
        prefix.PrefixFirst.whole = slow
        sys.exit(main(["view", sys.argv[1], "--size", "32"]))
    """))
    env = dict(os.environ, PYTHONPATH=str(Path(clwave.__file__).parents[1]))
    p = subprocess.Popen([sys.executable, str(script), str(clw)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, env=env, preexec_fn=sigint_default)
    watchdog = threading.Timer(120, p.kill)  # a line never printed: killed, the test fails below
    watchdog.start()
    try:
        while (line := p.stdout.readline()) and "reading the rest" not in line:
            pass
        assert line, "clwave view ended before reading the rest"
        time.sleep(0.5)
        p.send_signal(signal.SIGINT)
        ended = seconds_to_end(p, 30, "clwave view, Ctrl-C while the rest was read,")
    finally:
        watchdog.cancel()
        if p.poll() is None:
            p.kill()
        _, err = p.communicate()  # its pipes closed
    assert p.returncode == 0 and "clwave view: stopped" in err and "Traceback" not in err, err
    assert ended < 30


def test_a_render_while_another_thread_lets_the_coarse_stage_go(clw, monkeypatch):
    """The viewer's render thread in ``StagedTracer.render`` reads ``ready`` (False), then the full stage's set-up
    ends and the viewer's watching thread's ``wait()`` lets the coarse stage go, forced in that order: the render
    draws the coarse stage it took, the image the coarse stage of another tracer of the file draws."""
    camera = clwave.Camera(30.0, 20.0, 24)
    expect = clwave.RayTracer.open(clw).render(camera, tolerance=1e-1)
    staged, ready = clwave.RayTracer.open(clw), StagedTracer.ready

    def interleaved(self):
        answer = ready.fget(self)
        if not answer and self._thread.ident is not None:
            self._thread.join(60)  # the set-up ends now
            watch = threading.Thread(target=self.wait)  # the viewer's watching thread
            watch.start()
            watch.join(60)
        return answer

    staged.start()
    monkeypatch.setattr(StagedTracer, "ready", property(interleaved))
    result = staged.render(camera, tolerance=1e-1)
    assert staged.coarse is None and staged.full is not None  # the interleaving happened
    assert result.meta["stage"] == expect.meta["stage"] == "coarse"
    assert np.array_equal(result.image, expect.image)


def test_close_while_the_rest_is_read_stops_the_reader_and_the_full_stage_set_up(clw, monkeypatch):
    """``Viewer.close()`` while the rest of a file is read (3 s, instrumented) and the shaded views' full stage
    waits for it: the reader has stopped when close returns, and the set-up and its watching thread stop within a
    second, the full stage never made (given up, not set up from a model read after the stop)."""
    monkeypatch.setattr(view_prefix, "PREFIX", 2048)
    whole = PrefixFirst.whole
    monkeypatch.setattr(PrefixFirst, "whole", lambda self, **k: time.sleep(3.0) or whole(self, **k))

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(v.url.replace("/?", "/ws?"))
            await ws.receive_json()
            await ws.send_str(view_message(seq=1, mode="shaded"))
            while (await ws.receive(timeout=60)).type != aiohttp.WSMsgType.BINARY:
                pass

    v = view(clw, size=32, tolerance=2e-2)
    try:
        asyncio.run(asyncio.wait_for(go(v), 60))
        staged = v.server.sources["shaded"].staged
        deadline = time.monotonic() + 30

        def under_way():  # both: the set-up waits for the reader
            return v.server._reader.is_alive() and "clwave-staged-setup" in alive()

        while not under_way() and time.monotonic() < deadline:
            time.sleep(0.01)
        assert under_way()
    finally:
        v.close()
    assert "clwave-view-read" not in alive()
    deadline = time.monotonic() + 1.0
    while alive() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert not alive() and staged.full is None
    assert v.server.sources == {}  # the renderers let go


def test_a_tab_closed_while_the_ray_tracer_is_prepared_leaves_no_task(monkeypatch):
    """A tab that closes while its first shaded view waits for the ray tracer (held by a gate): no task of it is left
    pending on the server's loop (asyncio would report one destroyed while pending)."""
    from clwave.view.shaded import ShadedSource

    gate, prepare = threading.Event(), ShadedSource.prepare
    monkeypatch.setattr(ShadedSource, "prepare", lambda self: gate.wait(60) and prepare(self))
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=16), levels=1).threshold(keep=0.3)

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws, status = await shaded_view(s, v)
            await ws.close()
        deadline = time.monotonic() + 30
        while v.server.sessions and time.monotonic() < deadline:
            await asyncio.sleep(0.01)
        return status

    async def tasks():
        return [t.get_coro().__qualname__ for t in asyncio.all_tasks() if t is not asyncio.current_task()]

    try:
        with view(wv, size=16) as v:
            status = asyncio.run(asyncio.wait_for(go(v), 60))
            time.sleep(0.1)  # the cancelled tasks run to their end
            left = asyncio.run_coroutine_threadsafe(tasks(), v._background.loop).result(10)
            gate.set()  # the set-up goes on (the stop waits for it)
    finally:
        gate.set()
    assert status["type"] == "status" and "preparing" in status["message"]
    assert not v.server.sessions and not [name for name in left if name.startswith("Event.")], left


def test_shaded_views_go_on_with_the_coarse_stage_after_the_full_stages_set_up_fails(clw, monkeypatch):
    """Reading the rest failing fails the shaded views' full stage (it waits for that model): each tab hears it once,
    and the shaded views go on with the coarse stage, the model served from then on: a still view's whole image the
    coarse stage's (another tracer of the file's, within one grey level) and final, no frame of it a prefix, and a
    drag frame drawn, no error for either; X-ray views go on too."""
    monkeypatch.setattr(view_prefix, "PREFIX", 2048)
    monkeypatch.setattr(PrefixFirst, "whole", lambda self, **k: (_ for _ in ()).throw(
        clwave.FileFormatError("damaged")))
    receive = test_view_prefix.receive

    async def drawn(ws, seq, last):  # the view's frames until one that ``last`` says is its last, or its error
        frames = []
        while True:
            kind, message = await receive(ws)
            if kind == "error":
                return frames, message["message"]
            if kind == "frame" and message["seq"] == seq:
                frames.append(message)
                if last(message):
                    return frames, None

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(v.url.replace("/?", "/ws?"))
            await receive(ws)
            await ws.send_str(view_message(seq=1, mode="shaded"))
            told = []
            while len(told) < 2:  # the X-ray views' line and the shaded views'; any other error fails below
                kind, message = await receive(ws)
                if kind == "error":
                    told.append(message["message"])
            await ws.send_str(view_message(seq=2, mode="shaded", azimuth=40.0))
            still = await drawn(ws, 2, lambda f: f["reduction"] == 1)
            await ws.send_str(view_message(seq=3, mode="shaded", azimuth=50.0, moving=True))
            drag = await drawn(ws, 3, lambda f: True)
            await ws.send_str(view_message(seq=4, azimuth=60.0))
            xray = await drawn(ws, 4, lambda f: f["mime"] == "image/png" and f["coefficients"] == 2048)
            return told, still, drag, xray

    with view(clw, size=32, tolerance=2e-2) as v:
        told, (still, still_error), (drag, drag_error), (xray, xray_error) = asyncio.run(asyncio.wait_for(go(v), 120))
        shaded = v.server.sources["shaded"]
    assert sorted(m.partition(" views failed")[0] for m in told) == [
        "making the whole model for the X-ray", "making the whole model for the shaded"]
    assert (still_error, drag_error, xray_error) == (None, None, None)
    assert len(drag) == 1 and xray[-1]["seq"] == 4
    assert [(f["reduction"], f["final"], f["waiting"]) for f in still] == [(4, False, None), (1, True, None)]
    assert shaded.staged.failed and shaded.tracer is None
    camera = clwave.Camera(40.0, 20.0, 32, extent=still[-1]["extent"])
    expect = clwave.RayTracer.open(clw).render(camera, tolerance=2e-2)
    assert expect.meta["stage"] == "coarse"
    expect = expect.to_uint8(background=(0.0, 0.0, 0.0))
    assert expect.std() > 5 and np.abs(test_view_prefix.decode(still[-1]["data"]).astype(int) - expect).max() <= 1


def test_a_damaged_coarse_share_fails_the_shaded_views_alone(clw, tmp_path, monkeypatch):
    """A file whose coarse stage's summary is damaged (the details' field energy beyond the tiers'): reading it
    ahead of the rest fails quietly, the whole model is read and served to the X-ray views, and only the shaded
    views' coarse stage, reading it again, fails, with the file's one line (a shaded view's error, the X-ray views
    drawing on)."""
    receive = test_view_prefix.receive

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(v.url.replace("/?", "/ws?"))
            await receive(ws)
            await ws.send_str(view_message(seq=1, mode="shaded"))
            while (answer := await receive(ws))[0] == "status":  # "preparing the ray tracer"
                pass
            await ws.send_str(view_message(seq=2))
            while (drawn := await receive(ws))[0] != "frame":
                pass
            return answer, drawn

    monkeypatch.setattr(view_prefix, "PREFIX", 2048)
    bad = tmp_path / "bad.clw"
    shutil.copy(clw, bad)
    with h5py.File(bad, "r+") as h5:
        h5["g0/detail_field"][...] = np.array([0.0, 1e300])
    kept = clwave.WaveletVolume.open(bad).kept
    opened = PrefixFirst(bad)
    assert opened.whole(coarse_first=True).kept == kept
    with pytest.raises(clwave.FileFormatError, match="detail_field"):
        opened.coarse()
    with view(bad, size=32) as v:
        v.server.read_whole()
        deadline = time.monotonic() + 30
        while not v.server.sources["xray"].complete and time.monotonic() < deadline:
            time.sleep(0.01)
        assert v.server.sources["xray"].complete and v.server.wv.kept == kept
        (kind, answer), (_, drawn) = asyncio.run(asyncio.wait_for(go(v), 60))
    assert kind == "error" and answer["seq"] == 1 and "detail_field" in answer["message"]
    assert "\n" not in answer["message"] and drawn["seq"] == 2


def test_a_file_replaced_while_served_is_refused_by_the_coarse_stage(clw, tmp_path, monkeypatch):
    """The coarse stage's reading of a file is checked against the prefix as the whole's is: another volume in its
    place (another size and levels) is the replaced file's one line, the file itself passes."""
    monkeypatch.setattr(view_prefix, "PREFIX", 2048)
    served = tmp_path / "served.clw"
    shutil.copy(clw, served)
    opened = PrefixFirst(served)
    assert opened.coarse()[0].shape == opened.prefix.shape  # the file itself
    other = tmp_path / "other.clw"
    clwave.WaveletVolume.from_volume(clwave.phantom("shepp-logan", 24), levels=3).threshold(keep=0.05).save(other)
    os.replace(other, served)
    with pytest.raises(clwave.FileFormatError, match="replaced meanwhile"):
        opened.coarse()


def view_message(**fields) -> str:
    import json

    return json.dumps(dict(BASE, **fields))


async def shaded_view(session, v) -> tuple:
    """A socket of ``session`` to the viewer ``v`` that has asked for a shaded view, and the first message it heard
    back after the hello."""
    ws = await session.ws_connect(v.url.replace("/?", "/ws?"))
    await ws.receive_json()
    await ws.send_str(view_message(seq=1, mode="shaded"))
    return ws, await ws.receive_json(timeout=60)


def test_close_while_the_whole_is_ranked_does_not_wait_for_the_ranking(clw, monkeypatch):
    """The reader is waited for while it reads the file only: once read, its ranking (seconds at 1024^3) holds no
    lock of h5py's, and ``close()`` returns without waiting for it (the daemon reader then stops by itself)."""
    from clwave.splat import ranked

    monkeypatch.setattr(view_prefix, "PREFIX", 2048)
    ranking, release, rank = threading.Event(), threading.Event(), ranked.ranked_groups

    def slow(*a, **k):
        ranking.set()
        release.wait(60)
        return rank(*a, **k)

    monkeypatch.setattr(ranked, "ranked_groups", slow)
    v = view(clw, size=32, tolerance=2e-2)
    try:
        v.server.read_whole()
        assert ranking.wait(60), "the reader never ranked"
        start = time.perf_counter()
        v.close()
        assert time.perf_counter() - start < 5.0
    finally:
        release.set()
    v.server._reader.join(30)  # the daemon reader, released, ends by itself
    assert "clwave-view-read" not in alive()


@pytest.mark.parametrize("interpolate", [False, True], ids=["content mask", "interpolating, no mask"])
def test_close_during_the_shaded_tracers_build_of_a_model_in_memory_stops_it_at_a_slab(monkeypatch, interpolate):
    """``Viewer.close()`` while the shaded views' ray tracer of a model held in memory is built (its first slab held
    until the viewer stops, each later one until the test ends, as a long build would be): the build stops before
    its next slab (the tracer's ``abandon``), with a content mask or without (an interpolating model: until the
    seventeenth session nothing stopped its build), and close returns with no build thread left (the exit waited
    for the whole build before)."""
    from clwave.raytrace import bricks
    from clwave.view.shaded import ShadedSource

    building, stopping, release = threading.Event(), threading.Event(), threading.Event()
    expand, stop, slabs = bricks._expand_slab, ShadedSource.stop, []

    def slow(*args, **kwargs):
        slabs.append(1)
        if len(slabs) == 1:
            building.set()
            stopping.wait(60)
        else:
            release.wait(60)
        return expand(*args, **kwargs)

    monkeypatch.setattr(bricks, "_expand_slab", slow)
    monkeypatch.setattr(ShadedSource, "stop", lambda self: stop(self) or stopping.set())
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=32), levels=2,
                                          interpolate=interpolate).threshold(keep=0.2)
    assert (wv.content_mask is None) == interpolate

    async def go(v):
        async with aiohttp.ClientSession() as s:
            return (await shaded_view(s, v))[1]

    def builders():
        return [t.name for t in threading.enumerate() if t.name.startswith("clwave-view-build")]

    v = view(wv, size=16)
    try:
        status = asyncio.run(asyncio.wait_for(go(v), 60))
        assert building.wait(60), "the tracer's build never began"
        shaded = v.server.sources["shaded"]
        start = time.perf_counter()
        v.close()
        closed = time.perf_counter() - start
        left = builders()
    finally:
        release.set()
        v.close()
    assert "preparing the ray tracer" in status["message"]
    assert closed < 30 and not left and len(slabs) == 1 and shaded.tracer is None, (closed, left, len(slabs))


@pytest.mark.parametrize("first", ["stop", "reader"])
def test_a_stop_and_the_reader_settle_the_whole_model_once_in_either_order(clw, monkeypatch, first):
    """The whole model's Future is the reader's to settle once it has started: a stop that looks at it just before
    the reader sets it (forced: the reader's set waits for the stop's look, where the stop looks) or just after,
    neither fails; the Future holds the reader's model, and the reader ends."""
    from concurrent.futures import Future

    monkeypatch.setattr(view_prefix, "PREFIX", 2048)
    setting, looked, settled = threading.Event(), threading.Event(), threading.Event()

    class Interleaved(Future):
        def set_result(self, result):  # the reader's set: after the stop's look, where the order is "stop"
            setting.set()
            looked.wait(60)
            super().set_result(result)
            settled.set()

        def done(self):
            answer = super().done()
            if threading.current_thread().name != "clwave-view-read" and not looked.is_set():  # the stop's look
                looked.set()
                settled.wait(60)  # the reader sets it now
            return answer

    v = view(clw, size=32, tolerance=2e-2)
    v.server.whole = whole = Interleaved()
    if first == "reader":
        looked.set()
    v.server.read_whole()
    assert (settled if first == "reader" else setting).wait(60)
    v.close()  # the reader was done with the file: not waited for
    looked.set()  # where the stop did not look, the reader goes on
    v.server._reader.join(60)
    assert "clwave-view-read" not in alive() and whole.result(0).kept == clwave.WaveletVolume.open(clw).kept


def test_a_failing_stop_leaves_close_returning_and_the_loop_closed(monkeypatch, caplog):
    """``Viewer.close()`` when the server's stop raises (a bug): logged, and the loop still stopped and closed, its
    thread ended, close returning."""
    from clwave.view.server import ViewServer

    stop = ViewServer.stop

    async def failing(self):
        await stop(self)
        raise RuntimeError("a bug in the stop")

    monkeypatch.setattr(ViewServer, "stop", failing)
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=16), levels=1).threshold(keep=0.3)
    v = view(wv, size=16)
    v.close()
    assert not v._background.thread.is_alive() and v._background.loop.is_closed()
    assert any(r.getMessage() == "stopping the viewer failed" and r.exc_info for r in caplog.records)


class NoQueue:
    """A stand-in for a command queue: nothing to wait for."""

    def finish(self):
        pass


def paced_render(v, items=5000):
    """``(its Future, the counts launched)`` of a render of ``items`` launches paced at 0.01 s each on the viewer
    ``v``'s render thread, in bands as a kernel's (``kernels.in_bands``, whose bands check the thread's stop), once
    its first band started."""
    from clwave.device import kernels

    def launch(first, count):
        launched.append(count)
        time.sleep(0.01 * count)

    launched = []
    render = v.server.pool.submit(kernels.in_bands, NoQueue(), launch, items)
    while not launched:
        time.sleep(0.01)
    return render, launched


def small_viewer():
    return view(clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=16), levels=1).threshold(keep=0.6),
                size=16)


def test_a_stop_ends_the_render_under_way_within_a_launch():
    """The render and build threads take no KeyboardInterrupt: a stop ends their kernel launches between two bands
    (``threads.stop_on``), so that a long stage (a shaded still frame of seconds to minutes) does not hold the exit.
    A render of 5,000 items paced at 0.01 s each (50 s whole), on the server's render thread, ends within seconds of
    ``close()``; the main thread's own launches know no stop."""
    from clwave.device import kernels
    from clwave.threads import Abandoned

    v = small_viewer()
    render, launched = paced_render(v)
    start = time.monotonic()
    v.close()
    with pytest.raises(Abandoned, match="given up from another thread"):
        render.result(timeout=10)
    assert time.monotonic() - start < 10 and sum(launched) < 5000
    kernels.in_bands(NoQueue(), lambda first, count: None, 100)  # this thread has no stop event


def test_a_script_that_never_closes_its_viewer_ends_without_waiting_for_the_render(tmp_path):
    """A script starts a viewer, a render of 5,000 items paced at 0.01 s each (50 s whole) on its render thread, and
    ends without close(): the viewer is closed before the exit joins the render thread (view/main_end.py), which
    stops at its next band; until tidy22 the exit waited for the whole render."""
    script = tmp_path / "no_close.py"
    script.write_text(textwrap.dedent("""
        from test_view_threads import paced_render, small_viewer

        paced_render(small_viewer())
        print("rendering", flush=True)
    """))
    folders = (Path(clwave.__file__).parents[1], Path(__file__).parent)  # clwave's, and this module's
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(map(str, folders)))
    p = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env=env)
    try:
        assert "rendering" in p.stdout.readline()
        ended = seconds_to_end(p, 25, "a script that never closed its viewer, after its last line,")
    finally:
        if p.poll() is None:
            p.kill()
        _, err = p.communicate()
    assert p.returncode == 0 and "Traceback" not in err and "Exception ignored" not in err, err
    assert ended < 25


def test_a_viewer_that_fails_to_close_at_exit_is_logged_and_the_others_closed(caplog):
    """The exit hook closes every open viewer though one's close raises: it is logged, and the exception does not
    leave the hook (``threading._shutdown`` catches none: it skipped the thread pools' join; review22)."""
    from clwave.view import main_end

    class Server:
        def __init__(self, fails):
            self.fails, self.closed = fails, False

        def close(self):
            self.closed = True
            if self.fails:
                raise RuntimeError("its loop is gone")

    servers = [Server(True), Server(False)]
    for server in servers:
        main_end._open.add(server)
    try:
        main_end.close_all()
    finally:
        for server in servers:
            main_end._open.discard(server)
    assert all(server.closed for server in servers)
    assert "closing the viewer" in caplog.text and "its loop is gone" in caplog.text


@pytest.mark.parametrize("from_file", [False, True])
def test_a_shaded_source_prepared_after_the_stop_gives_up_quietly(from_file, tmp_path):
    """The build thread's stop (threads.stop_on) reaches every step of ``prepare``: a file's coarse stage and the
    warm-up render, not only a model's ``RayTracer`` (review21: the file's branch let ``Abandoned`` out into a Future
    nobody reads, "Future exception was never retrieved" on Ctrl-C); it makes no tracer and raises nothing."""
    from concurrent.futures import ThreadPoolExecutor

    from clwave.threads import stop_on
    from clwave.view.shaded import ShadedSource

    rgba = clwave.TransferFunction.preset("hydrogen").classify(clwave.phantom("hydrogen", n=16))
    wv = clwave.WaveletVolume.from_volume(rgba, levels=1).threshold(keep=0.3)
    path = None
    if from_file:
        path = tmp_path / "m.clw"
        wv.save(path)
    source = ShadedSource(wv, (16, 16), 1e-2, path=path)
    stop = threading.Event()
    stop.set()
    with ThreadPoolExecutor(1, initializer=stop_on, initargs=(stop,)) as builder:
        assert builder.submit(source.prepare).result(timeout=60) is None
    assert not source.ready()
