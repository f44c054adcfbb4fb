"""A tab's view as a command line, as Python and as an image saved at a chosen size (docs/viewer.md §5): the command
run in a shell and the Python run by ``exec`` give the server's image of the same view; the routes check what they
are sent.  The page's buttons in a real browser: tests/test_view_browser.py."""

import asyncio
import json
import re
import subprocess
import sys
import time
from pathlib import Path

import aiohttp
import numpy as np
import pytest

import clwave
from clwave.view import view
from clwave.view.export import Origin, Spec, command, python

from test_scale_bar import bar_rows
from test_view import BASE, decode, frames_until_final

#: the editor's preset moved, widened and made more opaque: no preset names it (a .json of points in the command)
TF = dict(preset="hydrogen", centre=0.1, width=1.5, opacity=2.0)


@pytest.fixture(scope="module")
def clw(tmp_path_factory):
    """A scalar .clw file small enough to be read whole at once (its prefix is all of it)."""
    model = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=24), levels=2).threshold(keep=0.2)
    return model.save(tmp_path_factory.mktemp("export") / "h.clw")


def post(v, route, body, headers=None):
    """``(status, bytes)`` of a POST of ``body`` (a dict, or text as it is) to ``route`` of the viewer ``v``."""
    async def go():
        async with aiohttp.ClientSession() as s:
            data = body if isinstance(body, str) else json.dumps(body)
            async with s.post(v.url.replace("/?", f"/{route}?"), data=data, headers=headers or {}) as r:
                return r.status, await r.read()
    return asyncio.run(go())


def final_frame(v, msg):
    """The figures and picture of the final frame of the view ``msg``."""
    async def go():
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(v.url.replace("/?", "/ws?"))
            await ws.receive_json()
            await ws.send_str(json.dumps(msg))
            return (await frames_until_final(ws, msg["seq"]))[-1]
    figures, data = asyncio.run(go())
    return figures, decode(data)


def exported(v, msg, size):
    """The command and the Python of the view ``msg`` at ``size``, and the image the server saves of it."""
    status, text = post(v, "export", dict(view=msg, size=list(size)))
    assert status == 200, text
    status, png = post(v, "image", dict(view=msg, size=list(size)))
    assert status == 200, png
    return json.loads(text), decode(png)


def shell(text, where: Path):
    """Run the command's text in bash in a new folder ``where``, ``clwave`` this checkout's; the picture it writes."""
    import os

    bin_dir = where / "bin"
    bin_dir.mkdir(parents=True)
    (bin_dir / "clwave").write_text(f'#!/bin/sh\nexec {sys.executable} -m clwave "$@"\n')
    (bin_dir / "clwave").chmod(0o755)
    env = dict(os.environ, PATH=f"{bin_dir}:{os.environ['PATH']}",
               PYTHONPATH=str(Path(clwave.__file__).parents[1]))
    done = subprocess.run(["bash", "-e", "-c", text], cwd=where, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return decode((where / "view.png").read_bytes())


def executed(text, where: Path, monkeypatch):
    """``exec`` the Python's text in a new folder ``where``; the picture it saves."""
    where.mkdir()
    monkeypatch.chdir(where)
    exec(compile(text, "<the viewer's Python>", "exec"), {})
    return decode((where / "view.png").read_bytes())


def ran_alike(text, snippet, where: Path, monkeypatch):
    """Run the command's text in-process in ``where`` and ``exec`` the Python in a folder of it: one picture, not blank,
    bit for bit."""
    from clwave.cli import main

    monkeypatch.chdir(where)
    assert main(text.split()[1:]) == 0
    got = decode((where / "view.png").read_bytes())
    assert got.std() > 5 and np.array_equal(executed(snippet, where / "alike", monkeypatch), got)


def grey(picture):
    """An X-ray picture's grey levels (a colour map's grey table repeats them in three channels)."""
    return picture[..., 0] if picture.ndim == 3 else picture


def test_an_xray_view_as_a_command_and_as_python_renders_the_servers_image(clw, tmp_path, monkeypatch):
    """An X-ray view (turned, zoomed, a window of its own) at the page's size and at twice it: the command's image is
    the saved one bit for bit, and the Python's too (all three splat every coefficient through a SplatRenderer of the
    same model, in the same order); the final frame on the page is within one grey level of it, not bit for bit: the
    viewer accumulates the same splats pass by pass (docs/viewer.md §2), a float32 sum in another order, which a
    rounding to 8 bits can move by one level."""
    with view(str(clw), size=(32, 40)) as v:
        lo, hi = v.server.sources["xray"].auto_window
        msg = dict(BASE, seq=1, azimuth=47.3, elevation=-12.5, zoom=1.7, window=[lo + 0.1 * (hi - lo), 0.7 * hi])
        figures, frame = final_frame(v, msg)
        page, saved = exported(v, msg, (32, 40))
        page2, saved2 = exported(v, msg, (64, 80))
    assert "--method splat" in page["command"] and "--window" in page["command"] and "--extent" in page["command"]
    got = shell(page["command"], tmp_path / "page")
    assert got.shape == (32, 40) and got.std() > 5 and np.array_equal(got, grey(saved))
    assert np.abs(got.astype(int) - grey(frame)).max() <= 1 and figures["final"]
    assert np.array_equal(executed(page["python"], tmp_path / "python", monkeypatch), got)
    twice = shell(page2["command"], tmp_path / "twice")
    assert twice.shape == (64, 80) and np.array_equal(twice, grey(saved2))


def test_an_xray_view_in_a_reversed_colour_map_as_a_command_and_as_python(clw, tmp_path, monkeypatch):
    """A view in inferno_r (M1, trial29): the command gets ``--colour-map inferno_r`` and the Python
    ``colour_map='inferno_r'``, no "not in this command" line; both pictures are the saved one bit for bit, in
    colour."""
    with view(str(clw), size=(32, 40)) as v:
        msg = dict(BASE, seq=1, azimuth=47.3, elevation=-12.5, colour_map="inferno_r")
        page, saved = exported(v, msg, (32, 40))
    assert "--colour-map inferno_r" in page["command"] and "#" not in page["command"]
    assert "colour_map='inferno_r'" in page["python"] and "not in this snippet" not in page["python"]
    got = shell(page["command"], tmp_path / "page")
    assert got.shape == (32, 40, 3) and np.array_equal(got, saved)
    assert np.array_equal(executed(page["python"], tmp_path / "python", monkeypatch), got)


def test_a_shaded_perspective_view_through_an_edited_function_as_a_command_and_python(clw, tmp_path, monkeypatch):
    """A shaded view of a scalar model through the editor's function (a preset moved, widened and more opaque: a .json
    of its points in the command), a perspective camera, a grey background: the command's image, the Python's, the
    saved one and the page's final frame are one image bit for bit (the final frame is clwave.raytrace of the view,
    docs/viewer.md §2); saved at twice the size, the command at that size again.  The starting function (grey, its
    window "auto": the tracer's percentiles) unlit: --tf grey --tf-window of those numbers, bit for bit again."""
    with view(str(clw), size=(32, 40), tolerance=2e-2) as v:
        msg = dict(BASE, seq=1, mode="shaded", tf=TF, azimuth=47.3, elevation=-12.5, zoom=1.3, fov=40.0,
                   background=0.25)
        figures, frame = final_frame(v, msg)
        page, saved = exported(v, msg, (32, 40))
        page2, saved2 = exported(v, msg, (64, 80))
        # the starting function, grey, whose window is "auto" (the tracer's pool percentiles, within the input's range:
        # from its least value, 0), unlit
        start = dict(BASE, seq=1, mode="shaded", azimuth=10.0, shading=False)
        start_figures, start_frame = final_frame(v, start)
        grey_page, grey_saved = exported(v, start, (32, 40))
    command_text = page["command"]
    # the lens zoomed 1.3 times: tan(fov / 2) 1.3 times less than at 40 degrees, the eye where 40 degrees frame zoom 1
    fov = float(re.search(r"--perspective --fov (\S+) --distance", command_text).group(1))
    assert np.tan(np.radians(fov) / 2) * 1.3 == pytest.approx(np.tan(np.radians(40.0) / 2), rel=1e-12)
    assert "--tf view-tf.json" in command_text
    assert "--tolerance 0.02" in command_text and "--background 0.25,0.25,0.25" in command_text
    got = shell(command_text, tmp_path / "page")
    assert figures["final"] and got.std() > 5 and np.array_equal(got, frame) and np.array_equal(got, saved)
    assert np.array_equal(executed(page["python"], tmp_path / "python", monkeypatch), got)
    twice = shell(page2["command"], tmp_path / "twice")
    assert twice.shape == (64, 80, 3) and np.array_equal(twice, saved2)
    lo, hi = start_figures["tf_window"]
    assert lo == 0.0 and f"--tf grey --tf-window {lo!r},{hi!r}" in grey_page["command"]
    assert "--no-shading" in grey_page["command"]
    got = shell(grey_page["command"], tmp_path / "grey")
    assert got.std() > 5 and np.array_equal(got, start_frame) and np.array_equal(got, grey_saved)


def test_a_command_line_viewers_model_options_go_into_the_command_and_the_python(tmp_path, monkeypatch):
    """``clwave view phantom:... --keep --levels --tf P --classify post``: its reading and model options (not the
    viewer's own) are the command's; a shaded view's function (a preset under a window of numbers: --tf P --tf-window)
    replaces the one given, an X-ray keeps it; the command run in-process and the Python's model (a volume read and
    decomposed as the command line does) give one image bit for bit."""
    from clwave.cli import main, make_parser

    args = make_parser().parse_args(["view", "phantom:hydrogen:20", "--keep", "0.3", "--levels", "2", "--tf",
                                     "hydrogen", "--classify", "post", "--size", "24", "--port", "0"])
    origin = Origin.of_args(args)
    assert origin.input == "phantom:hydrogen:20"
    assert [flag for _, flag, _ in origin.options] == ["--levels", "--keep", "--tf", "--classify"]
    extent = clwave.Camera(100.0, -30.0, (24, 28)).view(clwave.phantom("hydrogen", n=20)).pixel * 28
    camera = clwave.Camera(100.0, -30.0, (24, 28), extent=extent)
    tf = clwave.TransferFunction.preset("hydrogen", window=(0.02, 0.3))
    shaded = Spec("shaded", camera, tolerance=1e-2, background=0.1, tf=tf, levels=2)
    text = command(origin, shaded)
    assert text.count("--tf ") == 1 and "--tf hydrogen --tf-window 0.02,0.3" in text and "--classify post" in text
    xray = command(origin, Spec("xray", camera, window=(-1.0, 2.0), levels=2))
    assert "--tf hydrogen --classify post" in xray and "--window=-1.0,2.0" in xray
    monkeypatch.chdir(tmp_path)
    argv = text.split()
    assert argv[:2] == ["clwave", "render"] and main(argv[1:]) == 0
    got = decode((tmp_path / "view.png").read_bytes())
    assert got.std() > 5 and np.array_equal(executed(python(origin, shaded), tmp_path / "python", monkeypatch), got)


def test_the_routes_check_what_they_are_sent(monkeypatch):
    """``/export`` and ``/image`` need the token and a page of this server (another Origin: 403, as the socket); a
    request that is not ``{"view", "size"}`` with sides of 8 to 4096 pixels is one line (400), a body past 4 KiB is
    refused unread (413); a save while one is under way is refused (429), one that would outgrow memory is said so
    before it is rendered (507), and so is a part of the coefficients (detail kept) or a shaded view whose tracer is
    not made yet (409).  A model given in Python has no command line, and its Python says where the model comes
    from."""
    from clwave.view import export

    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=16), levels=1).threshold(keep=0.5)
    good = dict(view=dict(BASE, seq=1), size=[8, 8])
    with view(wv, size=16) as v:
        status, text = post(v, "export", good)
        assert status == 200
        texts = json.loads(text)
        assert texts["command"].startswith("# the model was given to clwave.view() in Python")
        assert "# wv: the model given to clwave.view()" in texts["python"]
        assert "clwave.splat(wv, camera)" in texts["python"]
        assert post(v, "export", dict(good, view=dict(BASE, seq=1, mode="shaded")))[0] == 409
        for size in ([0, 8], [8, 4097], [8], "x", [8.5, 8], [True, 8], None):
            status, line = post(v, "image", dict(good, size=size))
            assert status == 400 and line.decode().count("\n") == 1 and line.startswith(b"size="), (size, line)
        for body in ("not json", "[]", dict(view=dict(BASE, seq=1)), dict(good, more=1),
                     dict(good, view=dict(BASE, seq=1, zoom=500)), dict(good, view=dict(BASE, seq=1, fov=179))):
            status, line = post(v, "export", body)
            assert status == 400 and line.decode().count("\n") == 1, (body, line)
        assert post(v, "image", "x" * 5000)[0] == 413
        status, line = post(v, "image", dict(good, view=dict(BASE, seq=1, detail=0.5)))
        assert status == 400 and b"detail kept 50 %" in line
        assert post(v, "image", good, {"Origin": "http://evil.example"})[0] == 403
        assert post(v, "image", good, {"Origin": v.url.split("/?")[0]})[0] == 200

        async def no_token():
            async with aiohttp.ClientSession() as s:
                async with s.post(v.url.split("?")[0] + "image", data=json.dumps(good)) as r:
                    return r.status
        assert asyncio.run(no_token()) == 403
        loop = v._background.loop
        asyncio.run_coroutine_threadsafe(v.server.saving.acquire(), loop).result()
        try:
            status, line = post(v, "image", good)
            assert status == 429 and b"being saved already" in line
        finally:
            loop.call_soon_threadsafe(v.server.saving.release)
        monkeypatch.setattr(export, "SAVE_PIXEL_BYTES", 1 << 50)
        status, line = post(v, "image", good)
        assert status == 507 and line.startswith(b"saving a 8x8 image needs about")


def test_a_perspective_view_zooms_its_lens_and_keeps_its_eye():
    """In perspective the wheel narrows the field of view (tan of its half over the zoom) and the eye stays where the
    field of view frames the target's plane as the orthographic zoom 1 does: the target plane's pixel is the
    orthographic one at every zoom, and the eye is never brought into the content."""
    from clwave.view.frames import Source, ViewState

    vol = clwave.phantom("hydrogen", n=16)
    source = Source(vol, (24, 32))
    state = ViewState(seq=1, azimuth=20.0, elevation=10.0, zoom=1.0, mode="xray", detail=1.0, window=None,
                      moving=False, background=0.0, shading=True, fov=30.0)
    views = {zoom: source.camera(ViewState(**dict(state.__dict__, zoom=zoom))).view(vol) for zoom in (1.0, 4.0, 50.0)}
    flat = {zoom: source.camera(ViewState(**dict(state.__dict__, zoom=zoom, fov=None))).view(vol) for zoom in views}
    for zoom, v in views.items():
        assert np.array_equal(v.eye, views[1.0].eye) and v.perspective
        assert v.slope[0] * np.linalg.norm(v.eye - v.target) == pytest.approx(flat[zoom].pixel, rel=1e-12)
    radius = np.linalg.norm(np.array(vol.shape) * vol.spacing) / 2
    assert np.linalg.norm(views[1.0].eye - views[1.0].target) > 3 * radius


def test_a_clipped_shaded_view_as_a_command_and_python_and_an_xray_unclipped(clw, tmp_path, monkeypatch):
    """A shaded view through a crop box (negative corners: ``--clip-box=-...``) and a plane: the command's
    ``--clip-box``/``--clip-plane`` and the Python's ``clwave.Clip`` render the saved image and the page's final frame
    bit for bit, which differ from the unclipped view's; an X-ray of the same message is splatted whole (no clip in
    its command); a clip that keeps nothing is its one line (400)."""
    with view(str(clw), size=(32, 40), tolerance=2e-2) as v:
        lo, hi = v.server.hello()["model"]["box"]
        clip = dict(box=[lo[0], lo[1], lo[2] / 2, hi[0], hi[1] / 3, hi[2]], planes=[[0.0, 0.0, 0.0, 1.0, 0.2, -0.1]])
        msg = dict(BASE, seq=1, mode="shaded", azimuth=47.3, elevation=25.0, clip=clip)
        figures, frame = final_frame(v, msg)
        page, saved = exported(v, msg, (32, 40))
        _, whole = exported(v, dict(msg, clip=None), (32, 40))
        xray, _ = exported(v, dict(msg, mode="xray"), (32, 40))
        status, line = post(v, "image", dict(view=dict(msg, clip=dict(clip, box=[hi[0] + 100, 0, 0, hi[0] + 101, 1,
                                                                                     1])), size=[32, 40]))
    box = ",".join(map(repr, clip["box"]))
    assert f"--clip-box={box} --clip-plane 0.0,0.0,0.0,1.0,0.2,-0.1 " in page["command"]
    assert f"clip = clwave.Clip(lo=({', '.join(map(repr, clip['box'][:3]))})" in page["python"]
    assert "clip" not in xray["command"] and "clip" not in xray["python"]
    got = shell(page["command"], tmp_path / "page")
    assert figures["final"] and got.std() > 5 and np.array_equal(got, frame) and np.array_equal(got, saved)
    assert np.array_equal(executed(page["python"], tmp_path / "python", monkeypatch), got)
    assert np.abs(got.astype(int) - whole).max() > 20
    assert status == 400 and line.count(b"\n") == 1 and b"keeps nothing of the volume's content" in line


def test_a_view_with_its_scale_bar_as_a_command_and_as_python(clw, tmp_path, monkeypatch):
    """The page's scale bar ticked (``scale_bar``) on an orthographic X-ray: each frame names its length and label
    (--scale-bar's default for the view's extent), the command gets ``--scale-bar`` and the Python ``scale_bar=True``;
    the command's image is the saved one bit for bit, the bar round(length / pixel) pixels long in it; in perspective
    the frames name none and a save is refused in one line."""
    with view(str(clw), size=(96, 120)) as v:
        msg = dict(BASE, seq=1, azimuth=47.3, elevation=-12.5, zoom=1.7, scale_bar=True)
        figures, _ = final_frame(v, msg)
        page, saved = exported(v, msg, (96, 120))
        perspective, _ = final_frame(v, dict(msg, fov=30.0))
        status, line = post(v, "image", dict(view=dict(msg, fov=30.0), size=[96, 120]))
    length, label = figures["scale_bar"]
    assert label == f"{length:g} units" and figures["extent"] / 5 / 2.5 <= length <= figures["extent"] / 5
    assert page["command"].endswith(" --scale-bar -o view.png") and "scale_bar=True)" in page["python"]
    got = shell(page["command"], tmp_path / "page")
    assert np.array_equal(got, grey(saved))
    assert np.array_equal(executed(page["python"], tmp_path / "python", monkeypatch), got)
    assert bar_rows(got, 255)[0] == round(length / (figures["extent"] / 120))
    assert perspective["scale_bar"] is None
    assert status == 400 and line.count(b"\n") == 1 and b"a scale bar needs an orthographic view" in line


def test_an_opacity_unit_goes_into_the_command_and_the_python(tmp_path, monkeypatch):
    """``clwave view ... --tf hydrogen --opacity-unit 2``: a shaded view of the scalar kept (--classify post) through
    the tab's function, which holds the unit, is a .json of it in the command (no --opacity-unit beside it) and
    ``from_dict`` of it in the Python: one image bit for bit, not the image of the function per voxel; an X-ray of
    the volume classified before the transform keeps --tf hydrogen --opacity-unit 2, and its Python the preset's
    ``opacity_unit=2.0`` (it said the option was not in the snippet): one image again."""
    from clwave.cli import make_parser

    def origin_of(*more):
        return Origin.of_args(make_parser().parse_args(["view", "phantom:hydrogen:20", "--levels", "2", "--tf",
                                                        "hydrogen", "--opacity-unit", "2", *more]))
    camera = clwave.Camera(100.0, -30.0, (24, 28), extent=30.0)
    tf = clwave.TransferFunction.preset("hydrogen", window=(0.02, 0.3), opacity_unit=2.0)
    post_origin = origin_of("--classify", "post")
    shaded = Spec("shaded", camera, tolerance=1e-2, tf=tf, levels=2)
    text = command(post_origin, shaded)
    assert "--tf view-tf.json" in text and "--opacity-unit" not in text and '"opacity_unit": 2.0' in text, text
    got = shell(text, tmp_path / "shell")
    assert got.std() > 5
    assert np.array_equal(executed(python(post_origin, shaded), tmp_path / "python", monkeypatch), got)
    per_voxel = Spec("shaded", camera, tolerance=1e-2, tf=tf.under(opacity_unit=None), levels=2)
    assert not np.array_equal(executed(python(post_origin, per_voxel), tmp_path / "voxel", monkeypatch), got)
    pre_origin, xray = origin_of(), Spec("xray", camera, window=(0.0, 0.15), levels=2)
    text, snippet = command(pre_origin, xray), python(pre_origin, xray)
    assert "--tf hydrogen --opacity-unit 2.0" in text and "opacity_unit=2.0" in snippet and "not in" not in snippet
    ran_alike(text, snippet, tmp_path, monkeypatch)


@pytest.mark.parametrize("failure, line", [(clwave.FileFormatError("damaged"), "(damaged)"),
                                           (MemoryError(), "(internal error (MemoryError); see the server's log)")])
def test_a_failed_full_stage_is_its_line_not_still_being_made(clw, monkeypatch, failure, line):
    """A .clw whose shaded views' full stage fails to be set up (the whole model it takes raising): /export and /image
    of a shaded view answer 409 ("still being made") while it is set up, then 500 with one line naming the failure
    (they were 409 for ever), each time asked; an X-ray view still exports."""
    from clwave.view.shaded import ShadedSource

    monkeypatch.setattr(ShadedSource, "_whole_model", lambda self: (_ for _ in ()).throw(failure))
    body = dict(view=dict(BASE, seq=1, mode="shaded"), size=[16, 16])
    with view(str(clw), size=16) as v:
        deadline = time.monotonic() + 60
        while (answer := post(v, "export", body))[0] == 409 and time.monotonic() < deadline:
            time.sleep(0.2)
        answers = [answer, post(v, "export", body), post(v, "image", body)]
        xray = post(v, "export", dict(view=dict(BASE, seq=1), size=[16, 16]))
    for status, text in answers:
        text = text.decode()
        assert status == 500 and text.count("\n") == 1, (status, text)
        assert text == f"the shaded views' ray tracer of the whole file could not be made {line}: they show the " \
                       f"file's coarse stage, which no saved image or command draws\n"
    assert xray[0] == 200


@pytest.mark.parametrize("mode, size", [("xray", (1024, 1024)), ("shaded", (512, 512))])
def test_a_save_takes_turns_with_another_tabs_still_frames(clw, monkeypatch, mode, size):
    """A save is stages of the render thread taken in turn with the tabs' frames (docs/viewer.md §5): a tab's still
    view sent while a 1024^2 X-ray (a 512^2 shaded) save is under way has frames rendered between two of the save's
    stages (the render thread's log; the save's first stage waits until that tab's job has been queued, so the order
    does not depend on timing), and the image saved so is the one saved with nothing between its stages bit for bit,
    an X-ray the one a fresh renderer splats (clwave render's; a shaded one is the command's in the tests above).
    Until the twenty-first session a save was one stage, and a tab's 0.31 s still view waited 27.6 s behind a 2048^2
    X-ray one."""
    import threading

    from clwave.view import export

    log, save_began, tab_began = [], threading.Event(), threading.Event()
    picture = export.picture

    def gated(sources, spec):  # the save's stages, logged; after its first, waits for the tab's still view queued
        stages, first = picture(sources, spec), True
        while True:
            try:
                next(stages)
            except StopIteration as end:
                log.append("saved")
                return end.value
            log.append("save")
            if first:
                save_began.set()
                tab_began.wait(60)
                first = False
            yield

    with view(str(clw), size=(32, 40)) as v:
        source = v.server.sources[mode]
        frames = source.frames

        def logged(state, pace):  # made on the event loop, which queues its first stage at once (no await between)
            if state.seq == 2:
                tab_began.set()
            return (log.append(("tab", state.seq, frame.figures["final"])) or frame for frame in frames(state, pace))

        monkeypatch.setattr(source, "frames", logged)
        msg = dict(BASE, seq=1, mode=mode, azimuth=47.3, elevation=-12.5, zoom=1.7,
                   **(dict(window=list(v.server.sources["xray"].auto_window)) if mode == "xray" else dict(tf=TF)))

        async def go():
            loop = asyncio.get_running_loop()
            async with aiohttp.ClientSession() as s:
                ws = await s.ws_connect(v.url.replace("/?", "/ws?"))
                await ws.receive_json()
                await ws.send_str(json.dumps(msg))  # refined once (the whole file's tracer made), then again: the
                await frames_until_final(ws, 1)    # tab's still frames come at once, with no drag frame first
                monkeypatch.setattr(export, "picture", gated)
                saving = asyncio.ensure_future(s.post(v.url.replace("/?", "/image?"),
                                                      data=json.dumps(dict(view=msg, size=list(size)))))
                assert await loop.run_in_executor(None, save_began.wait, 60), "the save did not begin"
                await ws.send_str(json.dumps(dict(msg, seq=2)))
                still = await frames_until_final(ws, 2)
                async with await saving as answer:
                    assert answer.status == 200, await answer.text()
                    return still, await answer.read()

        still, png = asyncio.run(go())
        monkeypatch.setattr(export, "picture", picture)
        again = post(v, "image", dict(view=msg, size=list(size)))
    tab = [i for i, entry in enumerate(log) if entry[0] == "tab" and entry[1] == 2]
    assert tab and log[: tab[0]].count("save") == 1, log  # the tab's first still frame after the save's first stage
    assert "save" in log[tab[0]:] and log[-1] == "saved", log  # ... and before the save's next
    assert still[-1][0]["final"]
    saved = decode(png)
    assert again[0] == 200 and np.array_equal(saved, decode(again[1])) and saved.std() > 5
    if mode == "xray":
        camera = clwave.Camera(47.3, -12.5, size, extent=still[-1][0]["extent"])
        wv = clwave.WaveletVolume.open(clw)
        fresh = clwave.splat(wv, camera, renderer=clwave.SplatRenderer(wv)).to_uint8(tuple(msg["window"]))
        assert np.array_equal(grey(saved), fresh)


def test_a_viewers_noise_rule_goes_into_the_command_and_the_python(tmp_path, monkeypatch):
    """``clwave view NOISY.npy --wavelet linear --noise 3``: the command keeps ``--noise 3`` and the Python thresholds
    with ``noise=3.0``; the two give one image bit for bit."""
    from clwave.cli import make_parser

    z, y, x = np.mgrid[:20, :20, :20] / 20
    noisy = 10 * np.exp(-((x - .5) ** 2 + (y - .5) ** 2 + (z - .5) ** 2) / 0.04)
    noisy += np.random.default_rng(2).normal(0, 0.5, noisy.shape)
    np.save(tmp_path / "noisy.npy", noisy.astype(np.float32))
    args = make_parser().parse_args(["view", str(tmp_path / "noisy.npy"), "--wavelet", "linear", "--levels", "2",
                                     "--noise", "3", "--size", "24", "--port", "0"])
    origin = Origin.of_args(args)
    xray = Spec("xray", clwave.Camera(30.0, 20.0, 24, extent=30.0), window=(0.0, 200.0), levels=2)
    text, code = command(origin, xray), python(origin, xray)
    assert "--noise 3" in text and "threshold(noise=3.0)" in code and "not in this snippet" not in code
    ran_alike(text, code, tmp_path, monkeypatch)


def test_a_saved_images_renderer_warnings_come_with_it():
    """A saved image whose render warned (notes28 put such lines in a frame's note; a save kept them in the server's
    log) carries them in its response's X-Clwave-Note (JSON, which the page shows beside "saved"): a needle's X-ray
    names the needle, as its frames' note does; a shaded view through a clip box thinner than a pixel names the clip;
    a plain shaded view, none."""
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=16), levels=1).threshold(keep=0.6)
    lo, hi = (np.asarray(c) for c in clwave.model.camera._content_box(wv))
    tiny = dict(box=[*((lo + hi) / 2 - 1e-3), *((lo + hi) / 2 + 1e-3)], planes=[])
    rod = np.zeros((4, 4, 440), np.float32)
    rod[1:3, 1:3, 2:-2] = 1.0
    needle = clwave.WaveletVolume.from_volume(clwave.Volume(rod), levels=1)  # 218 times longer than wide

    def saved(v, msg):
        async def go():
            async with aiohttp.ClientSession() as s:
                body = json.dumps(dict(view=msg, size=[16, 16]))
                async with s.post(v.url.replace("/?", "/image?"), data=body) as r:
                    assert r.status == 200, await r.text()
                    note = r.headers.get("X-Clwave-Note")
                    return None if note is None else json.loads(note)
        return asyncio.run(go())

    with pytest.warns(clwave.ClwaveWarning, match="times longer than wide"), view(needle, size=16) as v:
        figures, _ = final_frame(v, dict(BASE, seq=1))
        note = saved(v, dict(BASE, seq=1))
    assert "times longer than wide" in note and note == figures["note"]
    with view(wv, size=16) as v:
        final_frame(v, dict(BASE, seq=1, mode="shaded"))  # its tracer made
        clipped = saved(v, dict(BASE, seq=1, mode="shaded", clip=tiny))
        plain = saved(v, dict(BASE, seq=1, mode="shaded"))
    assert "no ray met the model's content" in clipped and "a clip cuts it away" in clipped and plain is None


def test_the_orientation_letters_shown_are_in_the_saved_image_the_command_and_the_python(clw, tmp_path, monkeypatch):
    """The page's orientation letters shown (``edge_labels``): the saved image holds them at its edges, white outlined
    in black as the page draws them (a phantom: +x/−x... of the frame's camera), and is the image without them
    elsewhere; the command gets ``--edge-labels`` and the Python the letters, each giving the saved image bit for
    bit; unshown, the image is the plain one."""
    with view(str(clw), size=(96, 120)) as v:
        msg = dict(BASE, seq=1, azimuth=47.3, elevation=-12.5, edge_labels=True)
        figures, _ = final_frame(v, msg)
        page, saved = exported(v, msg, (96, 120))
        _, plain = exported(v, dict(msg, edge_labels=False), (96, 120))
    assert page["command"].endswith(" --edge-labels -o view.png")
    assert f"edge_labels={figures['orientation']!r})" in page["python"]
    saved, plain = grey(saved).astype(int), grey(plain).astype(int)
    # the letters' boxes, at most two axes' ("+x−y", 12-pixel font, 2-pixel margin) about each edge's middle
    middle = dict(left=np.s_[36:60, :40], right=np.s_[36:60, -40:], top=np.s_[:20, 40:80], bottom=np.s_[-20:, 40:80])
    outside = np.ones(saved.shape, bool)
    for edge, where in middle.items():
        outside[where] = False
        assert (saved[where] >= 200).sum() >= 6 and (saved[where] <= 5).sum() >= 6, edge  # white in black
    assert np.array_equal(saved[outside], plain[outside]) and not np.array_equal(saved, plain)
    ran_alike(page["command"], page["python"], tmp_path, monkeypatch)  # in-process: bash runs commands above
    assert np.array_equal(decode((tmp_path / "view.png").read_bytes()), saved)


@pytest.mark.parametrize("argv", [["--turntable", "3", "-o", "t.gif"], ["-o", "t.tif"]])
def test_edge_labels_without_a_png_picture_are_refused_in_one_line(tmp_path, capsys, monkeypatch, argv):
    from clwave.cli import main

    monkeypatch.chdir(tmp_path)
    assert main(["render", "phantom:hydrogen:16", "--size", "16", "--edge-labels", *argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--edge-labels writes letters into a PNG picture" in err
    assert list(tmp_path.iterdir()) == []
