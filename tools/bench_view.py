"""The bench's viewer cases (tools/bench.py; docs/viewer.md, docs/benchmarks.md §10): ``view`` and ``view-file`` in
headless chromium (tools/browser.py), ``view-held`` through the viewer's socket."""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from bench_common import peak_resident_gib, summary  # first: it puts the checkout on sys.path
from bench_scale import first_image_file

import clwave
from clwave.io.phantoms import phantom
from clwave.model.wavelet import WaveletVolume


def bench_view(args) -> dict:
    """``clwave view`` in headless chromium (tools/browser.py): hydrogen scalar, cubic, 3 levels, 5 % kept, at
    ``--view-image``.  X-ray: the first image after the page loads (the model ready, the server started), frames per
    second while dragging, and the time from releasing to the final (every kept coefficient) frame, each drag and
    release beside a one-shot splat of its final view (interleaved: a ratio the load changes less).  Shaded (the
    scalar through the hydrogen preset at render time, tolerance 1e-2): frames per second while dragging, release
    to the final frame beside a one-shot ``clwave.raytrace`` of it, and a transfer-function slider move to its first
    frame on the page."""
    import browser
    from clwave.view import view

    wv = WaveletVolume.from_volume(phantom("hydrogen", n=args.size), wavelet="cubic", levels=3).threshold(keep=0.05)
    size = args.view_image
    drag = drag_path(size)  # refused before anything starts
    start = time.perf_counter()
    first, fps, refine, drag_frame, drag_width, one_shot = [], [], [], [], [], []
    with view(wv, size=size, device=args.device) as viewer, browser.chromium() as driver:
        server_seconds = time.perf_counter() - start
        for run in range(args.views + 1):  # run 0 is the warm-up (the browser's first page)
            first_image = browser.open_viewer(driver, viewer.url)
            browser.wait_final(driver)
            moving, dragged = _view_drag(browser, driver, drag)
            browser.release(driver)
            final = browser.wait_final(driver)
            stats = driver.execute_script("return window.clwave.stats")
            t0 = time.perf_counter()
            clwave.splat(wv, clwave.Camera(final["azimuth"], final["elevation"], size, extent=final["extent"]))
            if run:
                one_shot.append(time.perf_counter() - t0)
                first.append(first_image)
                fps.append(len(moving) / dragged)
                refine.append((stats["frames"][-1]["at"] - stats["released"]) / 1000.0)
                drag_frame += [f["seconds"] for f in moving]
                drag_width += [f["width"] for f in moving]
        shaded = _view_shaded(browser, driver, viewer, wv, args, drag)
    return dict(setting=dict(volume=f"hydrogen {args.size}^3", channels=1, wavelet="cubic", levels=3, keep=0.05,
                             image=f"{size}^2", browser="headless chromium (Selenium)",
                             drag=_drag_words(drag)),
                coefficients=viewer.server.sources["xray"].r.count, server_start_seconds=server_seconds,
                xray=dict(first_image_seconds=summary(first), drag_frames_per_second=summary(fps),
                          drag_frame_render_seconds=summary(drag_frame), drag_frame_width=summary(drag_width),
                          refine_seconds=summary(refine), one_shot_splat_seconds=summary(one_shot),
                          refine_over_one_shot=statistics.median(r / o for r, o in zip(refine, one_shot))),
                shaded=shaded, peak_resident_gib=peak_resident_gib(),
                target=dict(first_image_seconds=0.3, drag_frames_per_second=10, refine_seconds=1.0,
                            shaded_drag_frames_per_second=5, tf_slider_first_frame_seconds=0.2))


def drag_path(size: int) -> tuple:
    """``(start, (dx, dy), moves)`` of the bench's drag on a ``size``² image: 15/32 of the image across and 15/128 down
    (240 x 60 pixels at 512²) in at most 60 moves of whole pixels (none down where that is under a pixel a move),
    pressed at ``start`` from the image's centre, an eighth of the image from its top (the page's status line covers
    its foot), so that it stays in the image.  Below 32 pixels the status line covers the image: refused."""
    if size < 32:
        raise SystemExit(f"--view-image {size}: the bench drags on images of at least 32 pixels (the page's status "
                         "line covers a smaller one)")
    across, down = size * 15 // 32, size * 15 // 128
    moves = min(60, across)
    dx, dy = across // moves * moves, down // moves * moves
    return (-(dx // 2), -(3 * size // 8)), (dx, dy), moves


def _drag_words(drag) -> str:
    _, (dx, dy), moves = drag
    return f"{moves} moves over {dx} x {dy} pixels, 50 ms apart"


def _view_drag(browser, driver, drag) -> tuple:
    """Drag (held) :func:`drag_path`'s moves 50 ms apart: the frames shown while moving, and the seconds it took."""
    start, (dx, dy), moves = drag
    shown = browser.shown(driver)
    t0 = time.perf_counter()
    browser.drag(driver, dx, dy, steps=moves, pause=0.05, start=start)
    dragged = time.perf_counter() - t0
    frames = driver.execute_script("return window.clwave.stats.frames")[-(browser.shown(driver) - shown):]
    return [f for f in frames if f["moving"]], dragged


def _view_shaded(browser, driver, viewer, wv, args, drag) -> dict:
    """The shaded mode of the page already open: a drag, its release to the final frame beside a one-shot ray trace
    of that view, and opacity-slider moves to their first frames."""
    size = args.view_image
    start = time.perf_counter()
    driver.execute_script('document.querySelector(\'input[value="shaded"]\').click();'
                          'const p = document.getElementById("tf-preset"); p.value = "hydrogen";'
                          'p.dispatchEvent(new Event("change"));')
    browser.wait_final(driver, timeout=600)
    ready = time.perf_counter() - start
    out = dict(first_final_seconds=ready, tolerance=1e-2, transfer_function="hydrogen preset, at render time")
    fps, frame, width, refine, one_shot = [], [], [], [], []
    for run in range(max(1, args.views)):
        moving, dragged = _view_drag(browser, driver, drag)
        browser.release(driver)
        final = browser.wait_final(driver, timeout=600)
        stats = driver.execute_script("return window.clwave.stats")
        fps.append(len(moving) / dragged)
        frame += [f["seconds"] for f in moving]
        width += [f["width"] for f in moving]
        refine.append((stats["frames"][-1]["at"] - stats["released"]) / 1000.0)
        source = viewer.server.sources["shaded"]
        t0 = time.perf_counter()
        source.tracer.render(clwave.Camera(final["azimuth"], final["elevation"], size, extent=final["extent"]),
                             tolerance=1e-2, transfer_function=source.transfer_function(
                                 ("hydrogen", 0.0, 1.0, 1.0), source.tracer)[0])  # (function, window)
        one_shot.append(time.perf_counter() - t0)
    slider = []
    for value in (60, 70, 80, 65, 55, 45, 40, 50):  # opacity-scale moves, each to its first frame on the page
        seq = driver.execute_script("return window.clwave.stats.frames.slice(-1)[0].seq")
        driver.execute_script(f"window.clwave.stats.tfInput = null; const e = document.getElementById('tf-opacity');"
                              f"e.value = {value}; e.dispatchEvent(new Event('input'));")
        shown = browser.wait_for(driver, f"const f = window.clwave.stats.frames.slice(-1)[0]; return f.seq > {seq} "
                                         f"&& f", timeout=120)
        slider.append((shown["at"] - driver.execute_script("return window.clwave.stats.tfInput")) / 1000.0)
        time.sleep(0.1)
    driver.execute_script("document.getElementById('tf-opacity').dispatchEvent(new Event('change'))")
    browser.wait_final(driver, timeout=600)
    return dict(out, drag_frames_per_second=summary(fps), drag_frame_render_seconds=summary(frame),
                drag_frame_width=summary(width), refine_seconds=summary(refine), one_shot_raytrace_seconds=summary(
                    one_shot), refine_over_one_shot=statistics.median(r / o for r, o in zip(refine, one_shot)),
                tf_slider_first_frame_seconds=summary(slider))


def bench_view_file(args) -> dict:
    """``clwave view FILE`` of a ``.clw`` file (``--first-image-file``; default: first-image's hydrogen ``--size``^3
    RGBA in ``--scratch``) at ``--view-image``, in a fresh process with headless chromium already running: seconds
    from the command's start to the printed address, from the page's start to its first image (and from the address),
    frames per second of a drag while the rest of the file is read, from the address to the final frame of the whole
    model, and the server's peak resident memory (docs/viewer.md §2); then, in another fresh process, the seconds from
    choosing the shaded mode on the page's first image to its first shaded frame (``RayTracer.open``'s coarse stage)."""
    import browser

    path, drag = first_image_file(args), drag_path(args.view_image)
    if not path.exists():
        raise SystemExit(f"{path} does not exist: run `bench.py first-image --size {args.size}` or give "
                         f"--first-image-file")
    command = [sys.executable, "-m", "clwave", "view", str(path), "--size", str(args.view_image), "--device",
               args.device]
    with browser.chromium() as driver:
        with _view_server(command) as (proc, url, address, log):
            start = time.perf_counter()
            first_image = browser.open_viewer(driver, url, timeout=600)
            first_wall = time.perf_counter() - start
            first = driver.execute_script("return window.clwave.current().fig")
            moving, dragged = _view_drag(browser, driver, drag)
            browser.release(driver)
            final = browser.wait_for(driver, "const c = window.clwave.current(); return c && c.fig.final && "
                                             "!c.fig.prefix && c.fig", timeout=900)
            final_wall = time.perf_counter() - start
            status = Path(f"/proc/{proc.pid}/status").read_text()
            peak = int(next(x for x in status.splitlines() if x.startswith("VmHWM")).split()[1]) / 2 ** 20
        with _view_server(command) as (proc, url, _, shaded_log):
            browser.open_viewer(driver, url, timeout=600)
            start = time.perf_counter()
            driver.execute_script('document.querySelector(\'input[value="shaded"]\').click()')
            shaded = browser.wait_for(driver, "const c = window.clwave.current(); return c.fig.mode === 'shaded' && "
                                              "c.fig", timeout=600)
            shaded_wall = time.perf_counter() - start
    return dict(setting=dict(file=str(path), image=f"{args.view_image}^2", browser="headless chromium (Selenium)",
                             drag=_drag_words(drag) + ", right after the first image"),
                address_seconds=address, first_image_seconds_from_page_start=first_image,
                first_image_seconds_after_address=first_wall, first_frame=dict(
                    coefficients=first["coefficients"], prefix=first["prefix"], width=first["width"]),
                drag_frames_per_second=len(moving) / dragged, drag_frame_width=summary([f["width"] for f in moving]),
                final_seconds_after_address=final_wall, final_coefficients=final["coefficients"],
                server_peak_resident_gib=peak, server_log=log,
                shaded_first_frame=dict(seconds_after_choosing=shaded_wall, width=shaded["width"],
                                        detail=shaded["detail"], prefix=shaded.get("prefix", False),
                                        server_log=shaded_log),
                target=dict(first_image_seconds_after_address=2.0))


@contextmanager
def _view_server(command):
    """``(process, address, seconds from its start to the address, its stderr lines)`` of a ``clwave view`` process,
    interrupted on leaving (the lines are filled in then)."""
    import signal

    start, log = time.perf_counter(), []
    with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                          cwd=Path(__file__).resolve().parents[1]) as proc:
        try:
            line = proc.stdout.readline()
            while line and "open http" not in line:
                line = proc.stdout.readline()
            yield proc, line.split()[-1], time.perf_counter() - start, log
        finally:
            proc.send_signal(signal.SIGINT)
            proc.wait(timeout=60)
            log += proc.stderr.read().splitlines()


def bench_view_held(args) -> dict:
    """The viewer's shaded views of a ``.clw`` file (``--first-image-file``; default: first-image's hydrogen
    ``--size``^3 RGBA in ``--scratch``) at ``--view-image``, in this process through its socket (no browser): after the
    page's first X-ray frame (which starts the reading of a large file's rest), the seconds from asking for a still
    shaded view to its first frame and to its final frame, the full stage's set-up, with the full stage taking the
    model the viewer holds or reads for its X-ray views (docs/viewer.md §2) against reading the file again
    (``held`` false), interleaved over ``--repeats`` rounds (tolerance 1e-2)."""
    import asyncio

    import aiohttp

    from clwave.raytrace import staged
    from clwave.view import view
    from clwave.view.protocol import unpack_frame

    path = first_image_file(args)
    if not path.exists():
        return dict(skipped=f"{path} does not exist: run `bench.py first-image --size {args.size}` or give "
                            f"--first-image-file")
    base = dict(type="view", azimuth=30.0, elevation=20.0, zoom=1.0, detail=1.0, window=None, moving=False,
                background=0.0, shading=True, tf=None)

    async def frames(ws, seq, until):
        while True:
            msg = await ws.receive(timeout=900)
            if msg.type == aiohttp.WSMsgType.BINARY:
                figures = unpack_frame(msg.data)[0]
                if figures["seq"] == seq and until(figures):
                    return figures

    async def session(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(v.url.replace("/?", "/ws?"))
            await ws.receive_json()
            await ws.send_str(json.dumps(dict(base, seq=1, mode="xray")))
            await frames(ws, 1, lambda f: True)
            start = time.perf_counter()
            await ws.send_str(json.dumps(dict(base, seq=2, mode="shaded")))
            await frames(ws, 2, lambda f: True)
            first = time.perf_counter() - start
            await frames(ws, 2, lambda f: f["final"] and not f.get("prefix"))
            return first, time.perf_counter() - start

    made = staged.StagedTracer.__init__
    runs = {True: [], False: []}
    try:
        for _ in range(args.repeats):
            for held in (False, True):
                staged.StagedTracer.__init__ = made if held else (
                    lambda self, *a, whole=None, **k: made(self, *a, **k))  # the file read again
                with view(path, size=args.view_image, tolerance=1e-2, device=args.device) as v:
                    first, final = asyncio.run(session(v))
                    runs[held].append(dict(first=first, final=final,
                                           full_setup=v.server.sources["shaded"].staged.full_seconds))
    finally:
        staged.StagedTracer.__init__ = made
    return dict(setting=dict(file=str(path), image=f"{args.view_image}^2", tolerance=1e-2, rounds=args.repeats),
                **{"held" if held else "read again": {k: summary([r[k] for r in rs]) for k in rs[0]}
                   for held, rs in runs.items()},
                rounds={"held" if held else "read again": rs for held, rs in runs.items()})
