"""The viewer's server without a browser (docs/viewer.md): tokens, hostile messages, superseded frames, the
frames themselves against the one-shot renderers.  The page in a real browser: tests/test_view_browser.py."""

import asyncio
import io
import json
import re

import aiohttp
import numpy as np
import pytest

import clwave
from clwave.view import view
from clwave.view.protocol import BURST, MAX_MESSAGE, RateLimit, Refused, parse_view, unpack_frame
from clwave.view.server import HEADERS, SCRIPTS, STATIC

BASE = dict(type="view", azimuth=30.0, elevation=20.0, zoom=1.0, mode="xray", detail=1.0, window=None, moving=False,
            background=0.0, shading=True)
TF = dict(preset="hydrogen", centre=0.1, width=2.0, opacity=2.0)
#: the editor's own points (data units), for a scalar hydrogen model: a red shell at 0.3 and a yellow core
POINTS = [[0.1, 0.2, 0.4, 1.0, 0.0], [0.3, 1.0, 0.1, 0.1, 0.08], [0.45, 1.0, 0.1, 0.1, 0.0], [0.9, 1.0, 0.9, 0.2, 0.2]]
#: a crop box (world x0, y0, z0, x1, y1, z1) and a plane (point, normal) of the page's clip
CLIP = dict(box=[-1.0, 0, 0, 1, 2, 3], planes=[[0, 0, 0, 0, 0, 1]])


@pytest.fixture(scope="module")
def viewer():
    with view(clwave.phantom("hydrogen", n=40), size=(48, 64), keep=0.2) as v:
        yield v


def socket_url(v):
    return v.url.replace("/?", "/ws?")


def run(coroutine):
    return asyncio.run(coroutine)


async def frames_until_final(ws, seq, until_seq=False, texts=None, most=None):
    """The frames of view ``seq`` up to its final one (others are dropped as a page drops them); ``until_seq``:
    its first frame only (a view while moving has no final one).  A status message (what is being made) and the
    histogram of a scalar model's values are passed over (into the list ``texts`` where given).  ``most``: at most
    that many frames before the final one (a bound in frames, not seconds: a first kernel build on an empty cache
    takes minutes of wall time on a loaded machine)."""
    out = []
    while True:
        assert most is None or len(out) < most, f"view {seq}: {most} frames and none final"
        msg = await ws.receive(timeout=300)
        if msg.type == aiohttp.WSMsgType.TEXT and json.loads(msg.data)["type"] in ("status", "histogram"):
            if texts is not None:
                texts.append(json.loads(msg.data))
            continue
        assert msg.type == aiohttp.WSMsgType.BINARY, msg
        figures, data = unpack_frame(msg.data)
        if figures["seq"] == seq:
            out.append((figures, data))
            if figures["final"] or until_seq:
                return out


def decode(data):
    import imageio.v3 as iio
    return iio.imread(io.BytesIO(data))


# ---------------------------------------------------------------------------- messages
def test_parse_view_takes_a_whole_view():
    state = parse_view(json.dumps(dict(BASE, seq=3, window=[0, 2.5])), 2, ("xray",))
    assert (state.seq, state.azimuth, state.window, state.moving, state.tf) == (3, 30.0, (0.0, 2.5), False, None)
    assert parse_view(json.dumps(dict(BASE, seq=3, tf=TF)), 2, ("xray",)).tf == ("hydrogen", 0.1, 2.0, 2.0)
    edited = parse_view(json.dumps(dict(BASE, seq=3, tf=dict(points=POINTS))), 2, ("xray",))
    assert edited.tf == clwave.TransferFunction(POINTS, name="edited") and edited.tf.window is None
    assert (state.colour_map, parse_view(json.dumps(dict(BASE, seq=3, colour_map="magma")), 2, ("xray",)).colour_map
            ) == ("grey", "magma")
    assert (state.scale_bar, parse_view(json.dumps(dict(BASE, seq=3, scale_bar=True)), 2, ("xray",)).scale_bar
            ) == (False, True)
    clip = parse_view(json.dumps(dict(BASE, seq=3, clip=CLIP)), 2, ("xray",))
    assert state.clip is None and state.clipping() is None
    assert clip.clip == ((-1.0, 0, 0, 1, 2, 3), ((0, 0, 0, 0, 0, 1),))
    assert clip.clipping() == clwave.Clip(lo=(-1, 0, 0), hi=(1, 2, 3), planes=[((0, 0, 0), (0, 0, 1))])
    plane = parse_view(json.dumps(dict(BASE, seq=3, clip=dict(box=None, planes=[[0, 0, 0, 1, 0, 0]]))), 2, ("xray",))
    assert plane.clipping() == clwave.Clip(planes=[((0, 0, 0), (1, 0, 0))])


@pytest.mark.parametrize("change, words", [
    (dict(seq=2), "above the last"), (dict(seq=True), "whole number"), (dict(azimuth="30"), "azimuth"),
    (dict(elevation=91), "elevation"), (dict(zoom=float("nan")), "zoom"), (dict(mode="shaded"), "mode"),
    (dict(detail=0), "detail"), (dict(window=[2, 1]), "lo < hi"), (dict(window="auto"), "window"),
    (dict(moving=1), "moving"), (dict(path="/etc/passwd"), "unknown field"), (dict(type="run"), "type"),
    (dict(scale_bar="yes"), "scale_bar='yes' must be true or false"),
    (dict(tf=[1]), "tf must be"), (dict(tf=dict(TF, preset="/etc/passwd")), "preset"),
    (dict(tf=dict(TF, opacity=-1)), "opacity"), (dict(tf=dict(TF, code="x")), "tf must be"),
    (dict(tf=dict(points=POINTS, preset="grey")), "tf must be"), (dict(tf=dict(points=POINTS[:1])), "2 to 32 rows"),
    (dict(tf=dict(points=[[v, 0, 0, 0, 0] for v in range(33)])), "2 to 32 rows"),
    (dict(tf=dict(points=[p[:4] for p in POINTS])), "2 to 32 rows"), (dict(tf=dict(points="x")), "2 to 32 rows"),
    (dict(tf=dict(points=[POINTS[0], [float("nan"), 0, 0, 0, 0]])), "tf point 1 value=nan"),
    (dict(tf=dict(points=[POINTS[0], [float("inf"), 0, 0, 0, 0]])), "tf point 1 value=inf"),
    (dict(tf=dict(points=[["0.1", 0, 0, 0, 0], POINTS[1]])), "tf point 0 value='0.1' must be a number"),
    (dict(tf=dict(points=[POINTS[0], [0.3, True, 0, 0, 0]])), "tf point 1 r=True"),
    (dict(tf=dict(points=[POINTS[0], [0.3, 0, 1.5, 0, 0]])), "tf point 1 g=1.5 must be a number from 0 to 1"),
    (dict(tf=dict(points=[POINTS[0], [0.3, 0, 0, 0, -0.1]])), "tf point 1 opacity=-0.1"),
    (dict(tf=dict(points=[POINTS[0], [0.3, 0, 0, 0, 1e4]])), "opacity=10000.0 must be a number from 0 to 1000"),
    (dict(tf=dict(points=[POINTS[1], POINTS[0]])), "strictly increasing"),
    (dict(tf=dict(points=[POINTS[0], POINTS[0]])), "strictly increasing"),
    (dict(tf=dict(points=[[0.0, 0, 0, 0, 0], [1e-31, 0, 0, 0, 1]])), "span 1e-31: at least 1e-30"),
    (dict(colour_map="jet"), "colour_map='jet' must be one of grey, bone, viridis, inferno, magma"),
    (dict(colour_map=None), "colour_map=None"), (dict(colour_map=["grey"]), "colour_map"),
    # JSON's whole numbers have no bound: 400 digits overflow a float (math.isfinite raised OverflowError)
    (dict(azimuth=10 ** 400), "azimuth=1000.* must be a number"), (dict(window=[0, -10 ** 400]), "hi="),
    (dict(tf=dict(points=[POINTS[0], [10 ** 400, 0, 0, 0, 0]])), "tf point 1 value="),
    (dict(clip=[1, 2]), "clip must be null or"), (dict(clip=dict(box=None)), "clip must be null or"),
    (dict(clip=dict(CLIP, code="x")), "clip must be null or"), (dict(clip=dict(CLIP, planes="x")), "clip must be"),
    (dict(clip=dict(CLIP, planes=[[0, 0, 0, 0, 0, 1]] * 7)), "at most 6"),
    (dict(clip=dict(CLIP, box=[0, 0, 0, 1, 1])), "clip box must be 6 numbers"),
    (dict(clip=dict(CLIP, planes=[[0, 0, 0, 0, 0, 1], "x"])), "clip plane 1 must be 6 numbers"),
    (dict(clip=dict(CLIP, box=[0, 0, 0, 1, 1, float("nan")])), "clip box=nan must be a number"),
    (dict(clip=dict(CLIP, planes=[[0, 0, 0, 0, True, 1]])), "clip plane 0=True must be a number"),
    (dict(clip=dict(CLIP, planes=[[0, 0, 10 ** 400, 0, 0, 1]])), "clip plane 0=1000.* must be a number"),
])
def test_parse_view_refuses_what_is_not_a_view(change, words):
    with pytest.raises(Refused, match=words):
        parse_view(json.dumps({**BASE, "seq": 3, **change}), 2, ("xray",))
    with pytest.raises(Refused, match="not JSON"):
        parse_view("{", 2, ("xray",))
    with pytest.raises(Refused, match="more than") as exc:
        parse_view(" " * (MAX_MESSAGE + 1), 2, ("xray",))
    assert exc.value.code == 1009
    with pytest.raises(Refused, match="nested too deep"):  # 4 KiB of brackets: past the recursion limit
        parse_view("[" * 2000 + "]" * 2000, 2, ("xray",))


def test_rate_limit_allows_a_burst_then_the_rate():
    now = [0.0]
    limit = RateLimit(rate=10.0, burst=5, clock=lambda: now[0])
    for _ in range(5):
        limit.take()
    with pytest.raises(Refused, match="messages a second"):
        limit.take()
    now[0] += 0.1  # one more token
    limit.take()


# ---------------------------------------------------------------------------- the server
def test_a_model_id_names_the_models_grid_and_values_not_how_many_coefficients_it_keeps():
    """The page applies a view it kept to a model of the same id only (docs/viewer.md §4): kept more or fewer of, a
    model is the same; another volume, spacing, number of levels or classification is not."""
    from clwave.view.protocol import model_id

    def model(volume, levels=2):
        return clwave.WaveletVolume.from_volume(volume, levels=levels)

    hydrogen = clwave.phantom("hydrogen", n=16)
    wv = model(hydrogen)
    same = model_id(wv)
    assert model_id(wv.threshold(keep=0.5)) == model_id(wv.threshold(keep=0.9)) == same and len(same) == 16
    others = [model(clwave.phantom("marschner-lobb", n=16)), model(hydrogen, levels=1),
              model(clwave.Volume(hydrogen.data, spacing=(2.0, 1.0, 1.0))),
              model(clwave.TransferFunction.preset("hydrogen").classify(hydrogen))]
    assert len({same, *map(model_id, others)}) == 5


def test_every_route_needs_the_token(viewer):
    async def go():
        async with aiohttp.ClientSession() as s:
            for path in (*STATIC, "/ws"):
                for query in ("", "?token=wrong", "?token=" + viewer.server.token[:-1]):
                    r = await s.get(viewer.url.split("/?")[0] + path + query)
                    assert r.status == 403, (path, query)
            page = await s.get(viewer.url)
            assert page.status == 200 and "text/html" in page.headers["Content-Type"]
            assert f"viewer.js?token={viewer.server.token}" in await page.text()
            assert "default-src 'self'" in page.headers["Content-Security-Policy"]
            missing = await s.get(viewer.url.replace("/?", "/../clwave/__init__.py?"))
            assert missing.status in (403, 404)
            other = await s.ws_connect(socket_url(viewer), headers={"Origin": "http://evil.example"})
            assert False, other  # pragma: no cover
    with pytest.raises(aiohttp.WSServerHandshakeError) as exc:
        run(go())
    assert exc.value.status == 403


def test_the_page_loads_every_script_served_in_order_each_with_the_headers(viewer):
    """index.html's <script> tags name server.SCRIPTS in their order (viewer.js, which opens the socket, last), and
    each comes back as JavaScript with the page's headers (the CSP among them); no script is served unloaded."""
    async def go():
        async with aiohttp.ClientSession() as s:
            page = await (await s.get(viewer.url)).text()
            served = {}
            for name in SCRIPTS:
                r = await s.get(viewer.url.replace("/?", f"/{name}?"))
                served[name] = r.status, r.content_type, r.headers, await r.text()
            return page, served
    page, served = run(go())
    assert re.findall(r'<script src="([\w-]+\.js)\?token=([\w-]+)"></script>', page) == [
        (name, viewer.server.token) for name in SCRIPTS]
    assert SCRIPTS[-1] == "viewer.js" and "new WebSocket(" in served["viewer.js"][3]
    for name, (status, mime, headers, text) in served.items():
        assert status == 200 and mime == "text/javascript" and text.startswith("// "), name
        assert all(headers[k] == v for k, v in HEADERS.items()), name
    assert {path for path, (_, mime) in STATIC.items() if mime == "text/javascript"} == {f"/{n}" for n in SCRIPTS}


def test_binds_loopback_only_by_default(viewer):
    assert viewer.server.host == "127.0.0.1" and viewer.url.startswith("http://127.0.0.1:")


@pytest.mark.parametrize("hostile", ["not json", json.dumps(dict(BASE, seq=1, path="/etc/passwd")),
                                     b"\x00binary", "x" * (2 * MAX_MESSAGE), "flood", "[" * 2000 + "]" * 2000,
                                     json.dumps(dict(BASE, seq=1, azimuth=10 ** 400)),
                                     # a reason whose 120th byte is inside a character: cut before it, valid UTF-8
                                     json.dumps(dict(BASE, seq=1, colour_map="a" + "é" * 100), ensure_ascii=False)])
def test_a_hostile_message_closes_only_its_connection(viewer, hostile, caplog):
    async def go():
        async with aiohttp.ClientSession() as s:
            good, bad = await s.ws_connect(socket_url(viewer)), await s.ws_connect(socket_url(viewer))
            for ws in (good, bad):
                assert (await ws.receive_json())["type"] == "hello"
            if hostile == "flood":
                for seq in range(1, BURST + 50):
                    await bad.send_str(json.dumps(dict(BASE, seq=seq, moving=True)))
            elif isinstance(hostile, bytes):
                await bad.send_bytes(hostile)
            else:
                await bad.send_str(hostile)
            closing = asyncio.get_running_loop().time() + 60  # the server's pings keep each receive waiting
            while (await bad.receive(timeout=60)).type not in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED):
                assert asyncio.get_running_loop().time() < closing, "the hostile tab was not closed within 60 s"
            assert bad.close_code in (1008, 1009) and bad.exception() is None  # a close, not a failed connection
            await good.send_str(json.dumps(dict(BASE, seq=1)))
            frames = await asyncio.wait_for(frames_until_final(good, 1), 60)  # a bound: it hung once in CI (flood)
            assert frames[-1][0]["final"]
    with caplog.at_level("WARNING", logger="clwave.view"):
        run(go())
    assert any("closed tab" in r.getMessage() for r in caplog.records)


def test_a_superseded_view_is_abandoned(viewer):
    async def go():
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(socket_url(viewer))
            await ws.receive_json()
            await ws.send_str(json.dumps(dict(BASE, seq=1)))
            await ws.send_str(json.dumps(dict(BASE, seq=2, azimuth=120.0)))
            seen = []
            while True:
                figures, _ = unpack_frame((await ws.receive(timeout=60)).data)
                seen.append((figures["seq"], figures["final"]))
                if figures["seq"] == 2 and figures["final"]:
                    return seen
    seen = run(go())
    old = [final for seq, final in seen if seq == 1]
    assert len(old) <= 1 and not any(old)  # at most the stage under way when view 2 came, never view 1's last
    assert [seq for seq, _ in seen if seq == 2] == [2] * (len(seen) - len(old))


def test_still_xray_frames_refine_to_the_splat_of_the_view(viewer):
    """The still view's frames: doubling prefixes, the last one clwave.splat of the same camera (within one grey
    level of the encoded PNG); a drag frame is a cheaper prefix, at the same view."""
    state = dict(BASE, seq=1, azimuth=75.0, elevation=-35.0, zoom=1.3, window=[0.0, 0.4])
    xray = viewer.server.sources["xray"]  # a new socket paces its own frames: the module's earlier drags do not count

    async def go():
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(socket_url(viewer))
            await ws.receive_json()
            await ws.send_str(json.dumps(dict(state, moving=True)))
            drag = unpack_frame((await ws.receive(timeout=60)).data)
            await ws.send_str(json.dumps(dict(state, seq=2)))
            return drag, await frames_until_final(ws, 2)
    (drag, _), frames = run(go())
    counts = [f["coefficients"] for f, _ in frames]
    total = xray.r.count
    assert counts == sorted(counts) and counts[-1] == total and drag["coefficients"] < total
    assert [f["error"] for f, _ in frames][-1] == 0.0
    final, data = frames[-1]
    assert final["mime"] == "image/png" and final["window"] == [0.0, 0.4]
    wv = viewer.server.wv
    camera = clwave.Camera(75.0, -35.0, (48, 64), extent=final["extent"])
    expect = clwave.splat(wv, camera).to_uint8((0.0, 0.4))
    got = decode(data)
    assert got.shape == expect.shape and expect.std() > 10
    assert np.abs(got.astype(int) - expect).max() <= 1


def test_the_largest_zoom_is_drawn_and_a_view_refused_is_told_on_the_page(viewer, monkeypatch):
    """At the page's largest zoom the still frames end at the splat of the view; a view whose footprints the host
    could not make is refused before any is made, its one line (naming the fix) sent to the page as an error, and
    the tab goes on."""
    from clwave.splat import textures
    from clwave.view.protocol import ZOOM

    async def go(seq, azimuth):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(socket_url(viewer))
            await ws.receive_json()
            await ws.send_str(json.dumps(dict(BASE, seq=seq, azimuth=azimuth, zoom=ZOOM[1])))
            while True:
                msg = await ws.receive(timeout=60)
                if msg.type == aiohttp.WSMsgType.TEXT and json.loads(msg.data)["type"] == "error":
                    return json.loads(msg.data)
                if msg.type == aiohttp.WSMsgType.BINARY and unpack_frame(msg.data)[0]["final"]:
                    return unpack_frame(msg.data)[0]
    assert run(go(1, 41.0))["extent"] == pytest.approx(viewer.server.sources["xray"].base_extent / ZOOM[1])
    monkeypatch.setattr(textures, "HOST_TEXEL_BYTES", 2**50)  # no footprint fits the host now
    error = run(go(2, 42.0))
    assert error["seq"] == 2 and "available" in error["message"] and "--method raytrace" in error["message"]
    monkeypatch.undo()
    assert run(go(3, 43.0))["final"]


def test_colour_maps_are_matplotlibs_tables_and_colour_the_grey_levels():
    """The stored tables are matplotlib's sampled at their 256 entries, rounded to 8 bits, and each ``_r`` the same
    sampled from the top down (within one level of matplotlib's own ``_r``, which re-samples a segmented map such as
    bone's); a grey ramp comes out as the table, row for row; the page gets the same rows."""
    import base64

    import matplotlib

    from clwave.view import colours

    ramp = np.arange(256, dtype=np.uint8).reshape(16, 16)
    assert colours.NAMES[0] == "grey" and colours.apply(ramp, "grey") is ramp
    assert colours.NAMES[8:] == ("grey_r", "bone_r", "viridis_r", "inferno_r", "magma_r", "seismic_r", "RdBu_r",
                                 "coolwarm_r")
    np.testing.assert_array_equal(colours.apply(ramp, "grey_r"), 255 - ramp)
    for name in colours.NAMES[1:]:
        mpl = name.replace("grey", "gray")
        order = np.arange(256)[::-1] if name.endswith("_r") else np.arange(256)
        expect = np.round(255 * matplotlib.colormaps[mpl.removesuffix("_r")](order)[:, :3]).astype(np.uint8)
        np.testing.assert_array_equal(colours.table(name), expect)
        if name != "grey_r":  # which stays grey: above
            np.testing.assert_array_equal(colours.apply(ramp, name).reshape(256, 3), expect)
        own = np.round(255 * matplotlib.colormaps[mpl](np.arange(256))[:, :3])
        assert np.abs(colours.table(name) - own).max() <= 1
    tables = colours.page_tables()  # what the page draws its colour bar from: the same rows, grey's the ramp
    assert list(tables) == list(colours.NAMES)
    for name, rows in tables.items():
        expect = np.column_stack([ramp.ravel()] * 3) if name.startswith("grey") else colours.table(name)
        expect = 255 - expect if name == "grey_r" else expect
        np.testing.assert_array_equal(np.frombuffer(base64.b64decode(rows), np.uint8).reshape(256, 3), expect)


def test_a_still_xray_frame_in_a_colour_map_is_the_splat_looked_up_in_its_table(viewer):
    """An X-ray view in inferno (a scalar model): every pixel of the final frame is a row of the table, and its row
    is the grey level of clwave.splat of the view under the same window (within one level, as the grey frames)."""
    from clwave.view.colours import table

    async def go():
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(socket_url(viewer))
            hello = await ws.receive_json()
            await ws.send_str(json.dumps(dict(BASE, seq=1, azimuth=60.0, window=[0.0, 0.4], colour_map="inferno")))
            return hello, await frames_until_final(ws, 1)
    hello, frames = run(go())
    assert list(hello["colour_maps"]) == ["grey", "bone", "viridis", "inferno", "magma", "seismic", "RdBu", "coolwarm",
                                          "grey_r", "bone_r", "viridis_r", "inferno_r", "magma_r", "seismic_r",
                                          "RdBu_r", "coolwarm_r"]  # reversed too (trial29 M1); diverging (signed30)
    assert hello["capabilities"]["xray"]["colour_map"] is True
    final, data = frames[-1]
    assert all(f["colour_map"] == "inferno" for f, _ in frames)
    got = decode(data)
    assert got.shape == (48, 64, 3)
    rows = table("inferno")
    match = np.all(got[:, :, None, :] == rows[None, None], axis=-1)  # (H, W, 256): the rows each pixel equals
    assert np.all(match.sum(axis=-1) == 1)  # every pixel one row of the table (inferno's rows are distinct)
    expect = clwave.splat(viewer.server.wv, clwave.Camera(60.0, 20.0, (48, 64), extent=final["extent"])).to_uint8(
        (0.0, 0.4))
    assert expect.std() > 10 and np.abs(match.argmax(axis=-1) - expect.astype(int)).max() <= 1


def test_the_editors_points_classify_the_shaded_view_and_rebuild_nothing(monkeypatch):
    """A scalar model's shaded view through the editor's own points (``tf: {"points": ...}``, data units): the tab
    hears the histogram of the values the "auto" window comes from, over the input's range, before the first shaded
    frame; every frame carries the points it was classified by and their span as its window; the final frame is
    clwave.raytrace of the view with TransferFunction(points) bit for bit.  From a preset to points, and a point moved,
    no bricks, program or scalar range is made (instrumented, as tests/test_classify.py): only the function's table and
    bounds."""
    from clwave.raytrace import classified, tracer as traced
    from clwave.raytrace.tracer import RayTracer

    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=24), levels=2).threshold(keep=0.3)
    moved = [p.copy() for p in POINTS]
    moved[1][0], moved[1][4] = 0.25, 0.12  # the shell's point dragged left and up
    metas, calls, render = [], [], RayTracer.render
    monkeypatch.setattr(RayTracer, "render", lambda self, *a, **k: (lambda r: metas.append(r.meta) or r)(
        render(self, *a, **k)))

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(socket_url(v))
            await ws.receive_json()
            texts = []
            await ws.send_str(json.dumps(dict(BASE, seq=1, mode="shaded", tf=TF)))
            await frames_until_final(ws, 1, texts=texts)
            tracer = v.server.sources["shaded"].tracer
            monkeypatch.setattr(traced, "build", lambda *a, **k: calls.append("build"))
            monkeypatch.setattr(classified.ScalarRange, "__init__", lambda *a, **k: calls.append("range"))
            programs, metas[:] = dict(tracer.cc.programs.made), []
            await ws.send_str(json.dumps(dict(BASE, seq=2, mode="shaded", tf=dict(points=POINTS), moving=True)))
            frames = await frames_until_final(ws, 2, until_seq=True)
            await ws.send_str(json.dumps(dict(BASE, seq=3, mode="shaded", tf=dict(points=moved), azimuth=50.0)))
            frames += await frames_until_final(ws, 3, texts=texts)
            assert calls == [] and dict(tracer.cc.programs.made) == programs and tracer.expansions == 1
            return texts, frames, tracer.scalar.sample
    with view(wv, size=32, tolerance=2e-2) as v:
        texts, frames, sample = run(go(v))
    monkeypatch.undo()  # the one-shot renders below make their own tracers
    histogram = [t for t in texts if t["type"] == "histogram"]
    assert len(histogram) == 1 and len(histogram[0]["counts"]) == 64 and sum(histogram[0]["counts"]) == sample.size
    # over the input's range, the sample clamped to it as the classification sees it (raytracing.md §10)
    lo, hi = wv.value_range
    assert histogram[0]["range"] == [lo, hi] and sample.size > 1000 and sample.min() < lo  # the model rings below 0
    assert histogram[0]["counts"] == np.histogram(np.clip(sample, lo, hi), 64, range=(lo, hi))[0].tolist()
    assert histogram[0]["field"] == [float(sample.min()), float(sample.max())] and histogram[0]["input"]
    assert [f["tf_points"] for f, _ in frames] == [POINTS] + [moved] * (len(frames) - 1)
    assert [f["tf_window"] for f, _ in frames] == [[0.1, 0.9]] * len(frames) and frames[-1][0]["final"]
    # every render classified by the points sent, a change paying its table and bounds only (0.5-0.7 ms here; the
    # bricks and programs cost seconds)
    sent = [clwave.TransferFunction(p, name="edited").to_dict() for p in (POINTS, moved)]
    assert [m["transfer_function"] for m in metas] == sorted((m["transfer_function"] for m in metas), key=sent.index)
    assert {json.dumps(m["transfer_function"]) for m in metas} == set(map(json.dumps, sent))
    assert 0 < max(m["classify_seconds"] for m in metas) < 0.25
    expect = clwave.raytrace(wv, clwave.Camera(50.0, 20.0, 32, extent=frames[-1][0]["extent"]), tolerance=2e-2,
                             transfer_function=clwave.TransferFunction(moved)).to_uint8(background=(0.0, 0.0, 0.0))
    other = clwave.raytrace(wv, clwave.Camera(50.0, 20.0, 32, extent=frames[-1][0]["extent"]), tolerance=2e-2,
                            transfer_function=clwave.TransferFunction(POINTS)).to_uint8(background=(0.0, 0.0, 0.0))
    got = decode(frames[-1][1])
    assert expect.std() > 5 and np.array_equal(got, expect) and np.abs(got.astype(int) - other).max() > 1


def test_the_editors_points_and_presets_keep_the_starting_functions_opacity_unit():
    """A viewer started with a function of opacity unit 2 (``--opacity-unit 2``): the editor's points and a preset
    picked from the list are per that unit too (the page's opacities are the starting function's numbers; they were
    per voxel): the final frames are clwave.raytrace of the view through those functions at unit 2 bit for bit, not
    per voxel."""
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=16), levels=1).threshold(keep=0.3)
    start = clwave.TransferFunction(POINTS, opacity_unit=2.0)
    hydrogen = dict(preset="hydrogen", centre=0.0, width=1.0, opacity=1.0)

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(socket_url(v))
            await ws.receive_json()
            finals = []
            for seq, tf in enumerate((dict(points=POINTS[1:]), hydrogen), 1):
                await ws.send_str(json.dumps(dict(BASE, seq=seq, mode="shaded", tf=tf)))
                finals.append((await frames_until_final(ws, seq))[-1])
            return finals
    with view(wv, size=32, tolerance=2e-2, tf=start) as v:
        finals = run(go(v))
    for (figures, data), tf in zip(finals, (clwave.TransferFunction(POINTS[1:]),
                                            clwave.TransferFunction.preset("hydrogen"))):
        camera = clwave.Camera(30.0, 20.0, 32, extent=figures["extent"])
        expect, per_voxel = (clwave.raytrace(wv, camera, tolerance=2e-2, transfer_function=tf.under(opacity_unit=unit))
                             .to_uint8(background=(0.0, 0.0, 0.0)) for unit in (2.0, None))
        got = decode(data)
        assert figures["final"] and expect.std() > 5 and np.array_equal(got, expect), tf
        assert np.abs(got.astype(int) - per_voxel).max() > 1


def test_a_starting_function_without_a_window_is_widened_over_its_points_span():
    """view(scalar model, tf=TransferFunction(points)) without a window (points in data units, as the editor's): the
    hello names its points' span as its window (the hello once failed on it), its frames are classified by it, and
    the editor's width doubled spreads its points over twice that span about its centre (the final frame
    clwave.raytrace with those points, made here in data units; within a grey level of the viewer's, which
    normalises them)."""
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=16), levels=1).threshold(keep=0.3)
    start, wide = dict(preset=None, centre=0.0, width=1.0, opacity=1.0), dict(preset=None, centre=0.0, width=2.0,
                                                                              opacity=1.0)

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(socket_url(v))
            hello = await ws.receive_json()
            out = []
            for seq, tf in enumerate((start, wide), 1):
                await ws.send_str(json.dumps(dict(BASE, seq=seq, mode="shaded", tf=tf)))
                out.append((await frames_until_final(ws, seq))[-1])
            return hello, out
    with view(wv, size=24, tolerance=2e-2, tf=clwave.TransferFunction(POINTS)) as v:
        hello, frames = run(go(v))
    assert hello["tf"] == dict(name=None, window=[0.1, 0.9])
    np.testing.assert_allclose([f["tf_window"] for f, _ in frames], [[0.1, 0.9], [-0.3, 1.3]], rtol=1e-15)
    for (figures, data), points in zip(frames, (POINTS, [[0.5 + 2 * (p[0] - 0.5), *p[1:]] for p in POINTS])):
        expect = clwave.raytrace(wv, clwave.Camera(30.0, 20.0, 24, extent=figures["extent"]), tolerance=2e-2,
                                 transfer_function=clwave.TransferFunction(points)).to_uint8(background=(0, 0, 0))
        assert figures["final"] and expect.std() > 5 and np.abs(decode(data).astype(int) - expect).max() <= 1


def test_device_memory_is_shared_out_among_the_renderers():
    """``memory_shares``: halves for the X-ray and the shaded views where both are served (a file's prefix and its
    whole model are one X-ray renderer, extended); never more than the cap together."""
    from clwave.view.server import memory_shares

    assert memory_shares(None, True) == dict(xray=None, shaded=None)
    assert memory_shares("1GiB", False) == dict(xray=2**30, shaded=None)
    assert memory_shares(1000, True) == dict(xray=500, shaded=500)
    cap = 2**30 + 7
    shares = memory_shares(cap, True)
    assert shares == dict(xray=cap // 2, shaded=cap - cap // 2) and shares["xray"] + shares["shaded"] == cap


def test_a_capped_viewer_streams_within_its_share_to_the_same_image():
    """``view(device_memory=)``: the X-ray renderer holds at most its share (its coefficients stream in chunks),
    the shaded tracer its own, and the still view's last frame is the uncapped splat of the view; a cap too small
    for the viewer is refused in one line naming the viewer's cap and the share."""
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=64)).threshold(keep=1.0)
    state = dict(BASE, seq=1, azimuth=75.0, elevation=-35.0, zoom=1.3, window=[0.0, 0.4])

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(socket_url(v))
            await ws.receive_json()
            await ws.send_str(json.dumps(state))
            return await frames_until_final(ws, 1)
    with view(wv, size=128, device_memory="28MiB") as v:
        frames = run(go(v))
        xray = v.server.sources["xray"].r
        assert xray.budget.cap == 14 * 2**20
        with pytest.raises(clwave.DeviceMemoryError) as refused:  # the tracer, as a tab's first shaded view makes it
            v.server.builder.submit(v.server.sources["shaded"].prepare).result()
        assert re.fullmatch(r"expanding the bricks .* allows 14 MiB .*; raise --device-memory, crop the volume or pick "
                            r"another --device \(within the shaded views' share of it \(docs/viewer.md §1\): "
                            r"device_memory=28 MiB\)", str(v.server.explain(refused.value, "shaded")))
        assert xray.chunk is not None and xray.chunk < xray.count  # streamed
    final, data = frames[-1]
    expect = clwave.splat(wv, clwave.Camera(75.0, -35.0, 128, extent=final["extent"])).to_uint8((0.0, 0.4))
    assert expect.std() > 10 and np.abs(decode(data).astype(int) - expect).max() <= 1
    with pytest.raises(clwave.DeviceMemoryError, match=r"device_memory=3 MiB is too small for this viewer: its "
                                                       r"X-ray views get 1.5 MiB of it .docs/viewer.md §1., and a"):
        view(wv, size=(48, 64), device_memory="3MiB")


def test_a_drag_prefix_with_the_footprints_of_its_bands_only_is_the_same_image(viewer):
    """``begin(camera, upto=n)`` makes the footprints of the bands the first n coefficients reach: their image
    equals the same prefix splatted into a view with every band's footprints, and it takes no more."""
    r = viewer.server.sources["xray"].r
    camera = clwave.Camera(40.0, 10.0, (40, 56))
    n = 600  # the scaling band and a few of the coarsest details
    prefix = r.begin(camera, upto=n)
    prefix.splat(0, n)
    full = r.begin(camera)
    full.splat(0, n)
    assert len(prefix.tables[0].textures) < len(full.tables[0].textures)
    assert np.allclose(prefix.image(), full.image(), rtol=1e-6, atol=1e-6 * np.abs(full.image()).max())
    with pytest.raises(ValueError, match="first 600 coefficients only"):
        prefix.splat(n, 1)


def test_still_frames_double_the_coefficients_and_end_at_the_kept_set(viewer):
    """Each still frame at least doubles the coefficients (about STILL_SECONDS more of splatting at the last still
    view's rate) and the rest goes at once when it is expected within 1.5 frames; before a first still view, passes
    double from the tab's drag prefix."""
    from clwave.view.frames import STILL_SECONDS

    xray = viewer.server.sources["xray"]
    limit, rate = 40_000, xray.rate
    try:
        xray.rate = STILL_SECONDS / 8000  # a frame's time splats 8000
        done, counts = 0, []
        while done < limit:
            done = xray._still_count(done, limit, 2048)
            counts.append(done)
        assert counts == [8000, 16000, 32000, 40000]  # 8000, doubling, then the last 8000 within 1.5 frames
        xray.rate = STILL_SECONDS / limit  # the whole view within a frame's time: one frame
        assert xray._still_count(0, limit, 2048) == limit
        xray.rate = None
        assert [xray._still_count(n, limit, 2048) for n in (0, 2048, 30000)] == [2048, 4096, limit]
    finally:
        xray.rate = rate


def test_a_model_without_coefficients_has_one_final_frame_a_view():
    """An all-zero volume (no coefficients): each still view ends in a final frame, with a note for the status line,
    after a bounded number of frames (it once spun without end, a thousand frames a second); the X-ray views are
    blank, the shaded view of it ends too."""
    from clwave.view.frames import NO_COEFFICIENTS, ZERO_FOG

    dark = dict(points=[[0.5, 1, 1, 1, 0], [1, 1, 1, 1, 1]])  # gives 0 no opacity

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(socket_url(v))
            hello = await ws.receive_json()
            views = []
            for seq, change in enumerate((dict(), dict(azimuth=90.0), dict(mode="shaded"),
                                          dict(mode="shaded", tf=dark)), 1):
                await ws.send_str(json.dumps(dict(BASE, seq=seq, **change)))
                views.append(await frames_until_final(ws, seq, most=8))  # it once spun without end
            return hello, views
    with view(np.zeros((16, 16, 16), np.float32), size=32) as v:
        hello, views = run(go(v))
    assert hello["model"]["coefficients"] == 0 and hello["modes"] == ["xray", "shaded"]
    assert [len(frames) for frames in views[:2]] == [2, 2]  # a view without a drag frame: one, then the final one
    assert len(views[2]) <= 8  # shaded: its details, coarse to full
    for frames in views:
        assert frames[-1][0]["final"]
    # X-ray: the line integrals of 0; shaded, the auto window (-0.5, 0.5) gives the data's 0 an opacity, which fogs
    # the data's box (docs/raytracing.md §10; against the direct render and the oracle in
    # test_a_still_shaded_view_ends_at_the_direct_render_whichever_view_came_first); a function that gives 0 none
    assert all(decode(frames[-1][1]).max() == 0 for frames in views[:2]) and decode(views[2][-1][1]).max() > 0
    assert decode(views[3][-1][1]).max() == 0
    assert all(f["note"] == NO_COEFFICIENTS and f["coefficients"] == 0 for frames in views[:2] for f, _ in frames)
    # the fog is not "nothing to show" (until notes28 it said so): the note says what the image is; blank, why
    assert all(f["note"] == ZERO_FOG for f, _ in views[2]) and "nothing to show" not in ZERO_FOG
    assert all(f["note"] == NO_COEFFICIENTS for f, _ in views[3])


#: volumes 16^3 of one value (None: the hydrogen phantom)
VOLUMES = dict(zeros=0.0, constant=0.7, tiny=1e-6, hydrogen=None)


@pytest.mark.parametrize("first", [True, False], ids=["shaded-first", "after-xray"])
@pytest.mark.parametrize("volume", list(VOLUMES))
def test_a_still_shaded_view_ends_at_the_direct_render_whichever_view_came_first(dirty_memory, volume, first):
    """A scalar volume's still shaded view (its starting function, grey through the auto window) ends at
    clwave.raytrace of the view bit for bit (issue #30), as the tab's first view or after two X-ray views, whatever
    the device memory held: an all-zero volume's was fog after X-ray views and blank as the first view, or the other
    way by what the heap held (its tracer's pool of no brick never written, read times weights 0; known-gaps §15).  A
    volume of one value is a fog over its data's box (the auto window (v - 0.5, v + 0.5) gives v opacity 0.5,
    docs/raytracing.md §10), within the tolerance of the oracle."""
    from clwave.raytrace.reference import classified_reference

    changes = ([] if first else [dict(), dict(azimuth=90.0)]) + [dict(mode="shaded", azimuth=50.0)]

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(socket_url(v))
            await ws.receive_json()
            for seq, change in enumerate(changes, 1):
                await ws.send_str(json.dumps(dict(BASE, seq=seq, **change)))
                frames = await frames_until_final(ws, seq, most=8)
            return frames[-1]
    value = VOLUMES[volume]
    data = np.asarray(clwave.phantom("hydrogen", n=16).data) if value is None else np.full((16,) * 3, value, np.float32)
    with view(data, size=32) as v:
        figures, picture = run(go(v))
        wv, shaded = v.server.wv, v.server.sources["shaded"]
    assert figures["final"] and figures["tf_window"] == list(shaded.tracer.scalar.window(shaded.start_tf))
    camera = clwave.Camera(50.0, 20.0, 32, extent=figures["extent"])
    direct = clwave.raytrace(wv, camera, tolerance=shaded.tolerance, transfer_function=shaded.start_tf)
    assert np.array_equal(decode(picture), direct.to_uint8(background=(0.0, 0.0, 0.0)))
    if value is not None:  # the oracle on a few of the view's rays (each costs it a tenth of a second)
        few = clwave.Camera(50.0, 20.0, 6, extent=figures["extent"])
        image = clwave.raytrace(wv, few, tolerance=shaded.tolerance, transfer_function=shaded.start_tf).image
        assert direct.image[..., 3].max() > 0.3 and image[..., 3].max() > 0.3
        assert np.abs(image - classified_reference(wv, few, shaded.start_tf)).max() <= shaded.tolerance


def test_shaded_frames_of_an_rgba_model_refine_in_detail_to_the_ray_traced_view(monkeypatch):
    """An RGBA model: a drag frame at a reduced size and coarse detail; when still, RayTracer.refine's frames,
    coarse detail on a reduced image to full detail, with error estimates, the last clwave.raytrace of the view.
    The first shaded view's wait for the tracer's build is counted in its time since the view, and said apart
    (``build_seconds``; a 16.5 s build showed as "253 ms since view")."""
    import time

    from clwave.view.shaded import ShadedSource

    prepare = ShadedSource.prepare
    monkeypatch.setattr(ShadedSource, "prepare", lambda self: time.sleep(0.5) or prepare(self))
    wv = clwave.WaveletVolume.from_volume(clwave.TransferFunction.preset("hydrogen").classify(
        clwave.phantom("hydrogen", n=24)), levels=2).threshold(keep=0.3)

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(socket_url(v))
            hello = await ws.receive_json()
            await ws.send_str(json.dumps(dict(BASE, seq=1, mode="shaded", azimuth=10.0, background=1.0, moving=True)))
            drag = await frames_until_final(ws, 1, until_seq=True)
            await ws.send_str(json.dumps(dict(BASE, seq=2, mode="shaded", azimuth=10.0, background=1.0)))
            return hello, drag, await frames_until_final(ws, 2)
    with view(wv, size=128, tolerance=2e-2) as v:  # a first frame on 32^2 (MIN_SIDE)
        hello, drag, frames = run(go(v))
    assert hello["modes"] == ["xray", "shaded"] and hello["capabilities"]["shaded"]["tf"] is False
    assert hello["capabilities"]["xray"]["colour_map"] is False  # its X-ray is in its own colours
    assert drag[0][0]["width"] < 128 and not drag[0][0]["final"]
    assert drag[0][0]["build_seconds"] >= 0.5
    assert drag[0][0]["elapsed"] - drag[0][0]["build_seconds"] >= drag[0][0]["seconds"]
    assert all(f["build_seconds"] == 0 for f, _ in frames)  # the tracer was built for the drag
    figures = [f for f, _ in frames]
    assert [f["detail"] for f in figures] == sorted(f["detail"] for f in figures)[::-1] and figures[-1]["detail"] == 0
    assert figures[0]["reduction"] > 1 and figures[-1]["reduction"] == 1 and figures[-1]["error"] == 0.0
    assert all(f["tolerance"] == 2e-2 for f in figures) and all(f["error"] >= 0 for f in figures[1:])
    expect = clwave.raytrace(wv, clwave.Camera(10.0, 20.0, 128, extent=figures[-1]["extent"]),
                             tolerance=2e-2).to_uint8(background=(1.0, 1.0, 1.0))
    assert np.abs(decode(frames[-1][1]).astype(int) - expect).max() <= 1


def test_a_clipped_shaded_view_rebuilds_nothing_and_a_clip_that_keeps_nothing_is_one_line(monkeypatch):
    """The tab's clip (docs/viewer.md §4): the hello gives the content's world box (the crop sliders' span); a clipped
    still view ends at clwave.raytrace of the view with that Clip; a clip that keeps nothing (the Clip's own refusal,
    or one beside the content: the tracer's) is one line for its view, and the tab goes on; a new clip, dragged and
    still, makes no bricks or programs (the half-spaces are the kernel's arguments)."""
    from clwave.raytrace import tracer as traced

    wv = clwave.WaveletVolume.from_volume(clwave.TransferFunction.preset("hydrogen").classify(
        clwave.phantom("hydrogen", n=24)), levels=2).threshold(keep=0.3)
    lo, hi = wv.content_box()
    half = dict(box=[lo[0], lo[1], lo[2], hi[0], (lo[1] + hi[1]) / 2, hi[2]], planes=[])
    cut = dict(box=None, planes=[[0.0, 0.0, 0.1, 0.3, 0.0, -1.0]])  # keeps below a tilted plane
    nothing = dict(box=None, planes=[[0, 0, 0, 1, 0, 0], [0, 0, 0, -1, 0, 0]])
    beside = dict(box=[hi[0] + 100, 0, 0, hi[0] + 101, 1, 1], planes=[])  # beyond the basis functions' reach
    calls = []

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(socket_url(v))
            hello = await ws.receive_json()
            await ws.send_str(json.dumps(dict(BASE, seq=1, mode="shaded", clip=half)))
            await frames_until_final(ws, 1)
            tracer = v.server.sources["shaded"].tracer
            monkeypatch.setattr(traced, "build", lambda *a, **k: calls.append("build"))
            programs = dict(tracer.cc.programs.made)
            errors = []
            for seq, clip in ((2, nothing), (3, beside)):
                await ws.send_str(json.dumps(dict(BASE, seq=seq, mode="shaded", clip=clip)))
                while (message := await ws.receive_json(timeout=60))["type"] != "error":
                    pass
                errors.append(message)
            await ws.send_str(json.dumps(dict(BASE, seq=4, mode="shaded", clip=cut, azimuth=60.0, moving=True)))
            await frames_until_final(ws, 4, until_seq=True)
            await ws.send_str(json.dumps(dict(BASE, seq=5, mode="shaded", clip=cut, azimuth=60.0)))
            frames = await frames_until_final(ws, 5)
            assert calls == [] and dict(tracer.cc.programs.made) == programs and tracer.expansions == 1
            return hello, errors, frames
    with view(wv, size=32, tolerance=2e-2) as v:
        hello, errors, frames = run(go(v))
    monkeypatch.undo()
    assert hello["model"]["box"] == [lo.tolist(), hi.tolist()]
    assert [e["seq"] for e in errors] == [2, 3] and "keeps nothing (no volume" in errors[0]["message"]
    assert "keeps nothing of the volume's content" in errors[1]["message"]
    assert all("\n" not in e["message"] for e in errors) and frames[-1][0]["final"]
    camera = clwave.Camera(60.0, 20.0, 32, extent=frames[-1][0]["extent"])
    clip = clwave.Clip(planes=[((0.0, 0.0, 0.1), (0.3, 0.0, -1.0))])
    expect = clwave.raytrace(wv, camera, tolerance=2e-2, clip=clip).to_uint8(background=(0.0, 0.0, 0.0))
    whole = clwave.raytrace(wv, camera, tolerance=2e-2).to_uint8(background=(0.0, 0.0, 0.0))
    got = decode(frames[-1][1])
    assert expect.std() > 5 and np.abs(got.astype(int) - expect).max() <= 1
    assert np.abs(got.astype(int) - whole).max() > 20


def test_a_scalar_model_is_shaded_through_the_tabs_transfer_function_built_off_the_render_thread(monkeypatch):
    """A scalar model: the editor's transfer function (a preset, its window moved and widened, its opacity scaled)
    classifies while rendering, the final frame clwave.raytrace with that function; the ray tracer is made on the
    build thread, and X-ray frames go on meanwhile."""
    import threading

    from clwave.view.shaded import ShadedSource

    gate, prepare = threading.Event(), ShadedSource.prepare
    monkeypatch.setattr(ShadedSource, "prepare", lambda self: gate.wait(60) and prepare(self))
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=24), levels=2).threshold(keep=0.3)

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(socket_url(v))
            hello = await ws.receive_json()
            await ws.send_str(json.dumps(dict(BASE, seq=1, mode="shaded", tf=TF)))
            status = await ws.receive_json()
            await ws.send_str(json.dumps(dict(BASE, seq=2)))  # X-ray while the tracer is being made
            xray = await frames_until_final(ws, 2)
            gate.set()
            await ws.send_str(json.dumps(dict(BASE, seq=3, mode="shaded", tf=TF, azimuth=50.0)))
            return hello, status, xray, await frames_until_final(ws, 3)
    with view(wv, size=32, tolerance=2e-2) as v:
        hello, status, xray, frames = run(go(v))
    assert hello["capabilities"]["shaded"]["tf"] is True and status["type"] == "status"
    assert xray[-1][0]["mode"] == "xray" and xray[-1][0]["final"]
    figures = [f for f, _ in frames]
    # 32^2: not reduced, the coarser details that halve the error (docs/raytracing.md §9), then the final frame
    assert len(figures) >= 2 and {f["reduction"] for f in figures} == {1} and figures[-1]["tolerance"] == 2e-2
    # hydrogen's window (0, 1): centre moved 0.1 of its width, twice as wide; opacity doubled
    points = clwave.TransferFunction.preset("hydrogen").points.copy()
    points[:, 4] *= 2.0
    tf = clwave.TransferFunction(points, window=(-0.4, 1.6))
    expect = clwave.raytrace(wv, clwave.Camera(50.0, 20.0, 32, extent=figures[-1]["extent"]), tolerance=2e-2,
                             transfer_function=tf).to_uint8(background=(0.0, 0.0, 0.0))
    assert expect.std() > 5 and np.abs(decode(frames[-1][1]).astype(int) - expect).max() <= 1


def test_a_transfer_function_that_shows_nothing_ends_blank_with_a_note():
    """A scalar model's shaded view through a window beyond its values (the editor's window moved off the data):
    the frames end, blank, and the status line says why."""
    from clwave.view.frames import NOTHING_VISIBLE

    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=16), levels=1).threshold(keep=0.3)

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(socket_url(v))
            await ws.receive_json()
            await ws.send_str(json.dumps(dict(BASE, seq=1, mode="shaded", tf=dict(TF, centre=2.0, width=0.02))))
            return await asyncio.wait_for(frames_until_final(ws, 1), 60)
    with view(wv, size=16) as v:
        frames = run(go(v))
    assert frames[-1][0]["final"] and decode(frames[-1][1]).max() == 0
    assert all(f["note"] == NOTHING_VISIBLE for f, _ in frames)


def test_a_views_renderer_warnings_are_its_frames_note_once_a_view_and_one_log_line(caplog):
    """The renderer's warnings reach the page (until notes28 they went to the server's stderr, attributed to
    concurrent/futures/thread.py, and the page showed a blank final frame and "refined"): a shaded view through a
    clip box thinner than a pixel round the content's centre meets nothing, and every frame of it says so, naming the
    clip; the same clip turned says it again (a tracer warns once; a view is told each time), a nearly opaque
    function's view its own warning, not the last view's, a plain view none; each line logged once whatever the views
    and frames, and none through Python's warnings (whose filters are the process's, not the render thread's).  The
    X-ray views of a needle (4 x 4 x 448 voxels, 112 times longer than wide: the content box's shape warns, not how
    it was made, and a spacing's needle splats slowly): the camera's warning, each view, and once to the caller of
    view() (the viewer's making, on its render thread)."""
    import warnings

    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=16), levels=1).threshold(keep=0.6)
    lo, hi = (np.asarray(c) for c in clwave.model.camera._content_box(wv))
    tiny = dict(box=[*((lo + hi) / 2 - 1e-3), *((lo + hi) / 2 + 1e-3)], planes=[])
    opaque = dict(points=[[-1, 1, 1, 1, 1000], [2, 1, 1, 1, 1000]])
    needle = clwave.WaveletVolume.from_volume(clwave.Volume(np.ones((448, 4, 4), np.float32)), levels=1)

    async def go(v, changes):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(socket_url(v))
            await ws.receive_json()
            views = []
            for seq, change in enumerate(changes, 1):
                await ws.send_str(json.dumps(dict(BASE, seq=seq, **change)))
                views.append(await asyncio.wait_for(frames_until_final(ws, seq), 120))
            return views
    with warnings.catch_warnings(record=True) as raised, caplog.at_level("WARNING", logger="clwave.view"):
        warnings.simplefilter("always")
        with view(wv, size=16) as v:
            shaded = run(go(v, [dict(mode="shaded", clip=tiny), dict(mode="shaded", clip=tiny, azimuth=60.0),
                                dict(mode="shaded", tf=opaque), dict(mode="shaded")]))
        assert not [w for w in raised if issubclass(w.category, clwave.ClwaveWarning)]
        with view(needle, size=48) as v:
            xray = run(go(v, [dict(), dict(colour_map="magma")]))
    # the viewer's making (on its render thread) warns its caller, at the caller's line (once a line where not "always")
    assert {w.filename for w in raised if "times longer than wide" in str(w.message)} == {__file__}
    logged = [r.getMessage() for r in caplog.records]
    for frames in shaded[:2]:
        assert frames[-1][0]["final"] and decode(frames[-1][1]).max() == 0
        assert all("no ray met the model's content" in f["note"] and "a clip cuts it away" in f["note"]
                   for f, _ in frames)
    assert all("nearly opaque" in f["note"] and "no ray met" not in f["note"] for f, _ in shaded[2])
    assert all("note" not in f for f, _ in shaded[3])
    assert all("times longer than wide" in f["note"] for frames in xray for f, _ in frames)
    for words in ("no ray met", "nearly opaque", "times longer than wide"):
        assert len([m for m in logged if words in m]) == 1, (words, logged)


def test_editor_points_the_models_subtraction_would_merge_are_refused_in_one_line_and_the_tab_goes_on():
    """A scalar model stored with -1000 subtracted (values near 0 kept as 1000 + v): the editor's points 1e-14
    apart, distinct in the input's units, would merge where the subtraction moves them (float64 spacing 1.1e-13 at
    1000): the page hears one line naming how far apart to set them, not the renderer's "not increasing", and the tab's
    next view, its points apart, ends at a final frame."""
    from clwave.model.volume import Volume

    vol = Volume(np.asarray(clwave.phantom("hydrogen", n=16).data) + 1000.0, subtracted=-1000.0)
    wv = clwave.WaveletVolume.from_volume(vol, levels=1).threshold(keep=0.6)
    close = [[0.0, 0.0, 0.0, 0.0, 0.0], [1e-14, 1.0, 1.0, 1.0, 0.2], [1.0, 1.0, 1.0, 1.0, 0.2]]

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(socket_url(v))
            await ws.receive_json()
            await ws.send_str(json.dumps(dict(BASE, seq=1, mode="shaded", tf=dict(points=close))))
            while (message := await ws.receive_json(timeout=60))["type"] != "error":
                pass
            await ws.send_str(json.dumps(dict(BASE, seq=2, mode="shaded", tf=dict(points=POINTS))))
            return message, await asyncio.wait_for(frames_until_final(ws, 2), 60)
    with view(wv, size=16) as v:
        error, frames = run(go(v))
    assert error["seq"] == 1 and error["message"] == ("transfer function values 0 and 1e-14 merge on the model's "
                                                      "values, stored as the input's minus the value subtracted, "
                                                      "-1000; set them at least 2.3e-13 apart")
    assert frames[-1][0]["final"] and frames[-1][0]["tf_points"] == POINTS


def test_a_scalar_model_is_classified_by_the_transfer_function_given_from_the_first_frame(monkeypatch):
    """view(scalar model, tf=) (what `clwave view scalar.clw --tf P --tf-window LO,HI` serves): the hello names the
    function for the page's editor, every render of the shaded source (its warm-up, the drag frame, each still frame)
    is classified by it, each frame reports its window, and the final still frame is clwave.raytrace of the view with
    it bit for bit (the viewer's tracer holds every detail; its full detail is the one-detail tracer's, docs/viewer.md
    §2)."""
    from clwave.raytrace.tracer import RayTracer

    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=24), levels=2).threshold(keep=0.3)
    tf = clwave.TransferFunction.preset("hydrogen", window=(0.1, 0.8))
    used, render = [], RayTracer.render
    monkeypatch.setattr(RayTracer, "render", lambda self, *a, **k: used.append(k.get("transfer_function")) or
                        render(self, *a, **k))
    start = dict(preset=None, centre=0.0, width=1.0, opacity=1.0)  # the page's editor at its start

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(socket_url(v))
            hello = await ws.receive_json()
            await ws.send_str(json.dumps(dict(BASE, seq=1, mode="shaded", tf=start, moving=True)))
            drag = await frames_until_final(ws, 1, until_seq=True)
            await ws.send_str(json.dumps(dict(BASE, seq=2, mode="shaded", tf=start, azimuth=50.0)))
            return hello, drag + await frames_until_final(ws, 2)
    with view(wv, size=32, tolerance=2e-2, tf=tf) as v:
        hello, frames = run(go(v))
    assert hello["tf"] == dict(name="hydrogen", window=[0.1, 0.8])
    assert len(used) >= 3 and all(u == tf for u in used)
    assert all(f["tf_window"] == [0.1, 0.8] for f, _ in frames) and frames[-1][0]["final"]
    expect = clwave.raytrace(wv, clwave.Camera(50.0, 20.0, 32, extent=frames[-1][0]["extent"]), tolerance=2e-2,
                             transfer_function=tf).to_uint8(background=(0.0, 0.0, 0.0))
    assert expect.std() > 5 and np.array_equal(decode(frames[-1][1]), expect)


def test_a_volume_classified_post_stays_scalar_with_its_transfer_function():
    """view(volume, tf=, classify="post") serves the scalar model carrying tf (its window resolved), which the shaded
    views start from; classify="pre" (the default) classifies it to RGBA first."""
    from clwave.view import as_model

    vol, tf = clwave.phantom("hydrogen", n=16), clwave.TransferFunction.preset("grey")
    post, pre = (as_model(vol, keep=0.2, tf=tf, classify=c) for c in ("post", "pre"))
    assert (post.channels, pre.channels) == (1, 4)
    assert clwave.TransferFunction.from_dict(post.transfer_function) == tf.resolved(vol) != tf  # "auto" made concrete
    assert as_model(vol, keep=0.2, tf="grey", classify="post").transfer_function == post.transfer_function  # a name
    with pytest.raises(clwave.InputError, match="classify='later' must be 'pre'"):
        as_model(vol, tf="grey", classify="later")


def test_view_refuses_what_it_cannot_show():
    with pytest.raises(clwave.InputError, match=r"volume file first .*clwave.view\(clwave.load\('volume.npy'\)\)"):
        view("volume.npy")
    with pytest.raises(clwave.InputError, match=r"WaveletVolume, a clwave.Volume, an array \(NumPy, Dask or an xarray "
                                                r"DataArray\) or a .clw file, got list"):
        view([1, 2])
    with pytest.raises(clwave.InputError, match=r"no voxel of this volume any opacity.*\(window=\(lo, hi\)\)"):
        view(np.full((8, 8, 8), 0.02, np.float32), tf="ct-bone")  # attenuation under a HU preset: nothing to see
    rgba = clwave.TransferFunction.preset("hydrogen").classify(clwave.phantom("hydrogen", n=8))
    with pytest.raises(clwave.InputError, match="4 channels .classified already.: leave tf out"):
        view(clwave.WaveletVolume.from_volume(rgba, levels=1), tf="hydrogen")
    with pytest.raises(clwave.InputError, match="has 4 channels: leave classify out"):
        view(rgba, tf="hydrogen", classify="post")
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=16), levels=1)
    with pytest.raises(clwave.InputError, match="classify='later' must be"):
        view(wv, classify="later")
    with pytest.raises(clwave.InputError, match="tolerance=0 must be a positive"):
        view(wv, tolerance=0)
    with pytest.raises(clwave.InputError, match="image size"):
        view(wv, size=0)


def test_view_returns_every_failure_to_start_to_its_caller(monkeypatch):
    """``view(..., port=70000)`` (or -1, or a port in use) raised in the server's thread and left view() waiting
    forever: a port out of range is refused before any work, and any failure of the server's start reaches the
    caller (a busy port: one line naming another port or 0)."""
    import socket
    import threading

    from clwave.view.server import ViewServer

    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=8), levels=1)

    def view_within(seconds=60, **kw):  # a hang fails the test instead of stopping it
        outcome = []
        thread = threading.Thread(target=lambda: outcome.append(_raised(view, wv, size=16, **kw)), daemon=True)
        thread.start()
        thread.join(seconds)
        assert outcome, f"view({kw}) did not return"
        return outcome[0]

    for port in (70000, -1, 80.5, "80"):
        assert re.fullmatch(rf"port={port!r} must be from 0 \(a free port\) to 65535", str(view_within(port=port)))
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        exc = view_within(port=port)
        assert isinstance(exc, clwave.InputError) and re.fullmatch(
            rf"cannot listen on 127.0.0.1:{port} \(.+\); choose another port=, or port=0 for a free one", str(exc))

    async def fails(self):
        raise RuntimeError("no loop")

    monkeypatch.setattr(ViewServer, "start", fails)
    assert str(view_within()) == "no loop"


def _raised(call, *args, **kw):
    """The exception ``call(*args, **kw)`` raised (its result closed if it returned)."""
    try:
        call(*args, **kw).close()
    except Exception as exc:
        return exc


def test_cli_view_refuses_bad_options_before_any_work(capsys, tmp_path):
    """What `render` refuses of --tf/--tf-window, `view` refuses in the same words (one home, cli/options.py)."""
    from clwave.cli import main

    rgba = clwave.WaveletVolume.from_volume(clwave.TransferFunction.preset("hydrogen").classify(
        clwave.phantom("hydrogen", n=8)), levels=1).save(tmp_path / "rgba.clw")
    for argv, words in [(["--port", "70000"], "--port 70000 must be from 0"), (["--tolerance", "0"], "--tolerance"),
                        (["--tf-window", "0,1"], "give --tf too"), (["--tf", "bone"], "bone"),
                        (["--tf", "hydrogen", "--tf-window", "1"], "--tf-window '1' must be 2"),
                        ([str(rgba), "--tf", "hydrogen"], "4 channels (classified already): leave them out"),
                        (["--device-memory", "2x"], "--device-memory 2x is not a size")]:
        assert main(["view", *([] if argv[0].endswith(".clw") else ["phantom:hydrogen:16"]), *argv]) == 2, argv
        assert words in capsys.readouterr().err, argv


def test_cli_view_refuses_a_device_memory_too_small_for_its_size_at_start(capsys, tmp_path):
    """``clwave view --size 2048 --device-memory 120MiB``: the X-ray views' 60 MiB hold the 128x128 auto-window image
    and the drag frames, not the still 2048x2048 view (125 MiB, SplatRenderer's plan; 90 MiB before its footprints,
    where it is refused first since the twentieth session): refused at start-up in one line in the command line's
    words, not on the page at every still view.  (A 256x256 view of this 16^3 model needed
    187 MiB while splatting's textures grew with the magnification; now about as much as a 128x128 one.)"""
    from clwave.cli import main

    path = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=16)).save(tmp_path / "h.clw")
    assert main(["view", str(path), "--size", "2048", "--device-memory", "120MiB"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and re.fullmatch(r"clwave: error: --device-memory 120 MiB is too small for this viewer: its "
                                          r"X-ray views get 60 MiB of it \(docs/viewer.md §1\), and a 2048x2048 view "
                                          r"needs at least 90 MiB of device memory before its footprints .*; give more "
                                          r"or a smaller --size \(at most 16\d\dx16\d\d here\)", err[0]), err


def test_cli_view_refuses_a_size_beyond_the_device_before_reading_the_input(capsys, tmp_path, monkeypatch):
    """``clwave view IN --size N`` past the ray tracer's one-buffer limit (N*N*32 bytes over the device's largest
    buffer, the rule `render --method raytrace` refuses by): one line naming the size asked, the limit and the fix,
    before the input is read (a file that is not a volume is never opened).  The host's memory is made ample here:
    its own rule is the next test's."""
    from math import isqrt

    from clwave.cli import main
    from clwave.device import memory
    from clwave.device.context import ComputeContext

    monkeypatch.setattr(memory, "available_bytes", lambda: 2**60)

    info = ComputeContext.get(None).info
    own = min(info.max_alloc, info.global_mem)
    most = isqrt(own // 32)
    junk = tmp_path / "junk.npy"
    junk.write_bytes(b"not a volume")
    for size in (f"{most + 1}", f"2x{own // 64 + 1}", "99999"):
        assert main(["view", str(junk), "--size", size]) == 2, size
        err = capsys.readouterr().err.strip().splitlines()
        h, _, w = size.partition("x")
        assert len(err) == 1 and f"the viewer's {h}x{w or h} shaded image needs" in err[0] and \
            f"give a smaller --size (at most {most}x{most} here)" in err[0], err
    assert main(["view", str(junk), "--size", str(most)]) == 2  # within the limit: the input is read, and refused
    assert "junk.npy" in capsys.readouterr().err


def test_cli_view_refuses_a_size_whose_images_outgrow_host_memory_before_reading_the_input(capsys, tmp_path,
                                                                                         monkeypatch):
    """``clwave view IN --size N`` within the device's one-buffer limit whose images (``VIEW_PIXEL_BYTES`` a pixel)
    need more host memory than the machine has available, on a CPU device (its memory the host's): one line naming
    the need, what is available and the largest size that fits, before the input is read; that largest size is not
    refused for it.  A device of its own is not held to it (the input is read)."""
    from math import isqrt

    from clwave.cli import main
    from clwave.cli import view as cli_view
    from clwave.device import memory
    from clwave.device.context import ComputeContext

    monkeypatch.setattr(memory, "available_bytes", lambda: 64 * 2**20)
    most = isqrt(64 * 2**20 // cli_view.VIEW_PIXEL_BYTES)
    junk = tmp_path / "junk.npy"
    junk.write_bytes(b"not a volume")
    if ComputeContext.get(None).info.kind != "CPU":
        assert main(["view", str(junk), "--size", str(most + 1)]) == 2
        assert "junk.npy" in capsys.readouterr().err
        return
    for size, (h, w) in ((f"{most + 1}", (most + 1, most + 1)), (f"{most}x{4 * most}", (most, 4 * most))):
        assert main(["view", str(junk), "--size", size]) == 2, size
        err = capsys.readouterr().err.strip().splitlines()
        need = memory.format_size(h * w * cli_view.VIEW_PIXEL_BYTES)
        assert len(err) == 1 and f"a viewer of {h}x{w} images needs about {need}, and this machine has 64 MiB " \
            f"available; give a smaller --size (at most {most}x{most} here now)" in err[0], err
    assert main(["view", str(junk), "--size", str(most)]) == 2  # within it: the input is read, and refused
    assert "junk.npy" in capsys.readouterr().err


def test_cli_view_of_a_volume_classified_post_starts_from_its_transfer_function(monkeypatch):
    """``clwave view VOLUME --tf P --tf-window LO,HI --classify post``: the server gets the scalar model and starts its
    shaded views from that function (the model's own, as `render` takes it); without --classify, an RGBA model."""
    from clwave.cli import main
    from clwave.view import server

    class Served(Exception):
        pass

    def record(model, size, **options):
        raise Served(model, options["transfer_function"])
    monkeypatch.setattr(server, "ViewServer", record)
    tf = clwave.TransferFunction.preset("hydrogen", window=(0.1, 0.8), opacity_unit=1.0)  # as resolved records it
    for post, channels, given in (["--classify", "post"], 1, tf), ([], 4, None):
        with pytest.raises(Served) as served:
            main(["--debug", "view", "phantom:hydrogen:16", "--tf", "hydrogen", "--tf-window", "0.1,0.8", *post])
        model, start = served.value.args
        assert model.channels == channels and start == given


def test_cli_view_serves_a_scalar_file_classified_by_tf_until_interrupted(tmp_path):
    """``clwave view scalar.clw --tf P --tf-window LO,HI`` (opened by its prefix, here all of a small file) prints the
    address with its token; the page needs the token; the hello names the function for the page's editor; every
    shaded frame is classified under that window, and the final still frame is clwave.raytrace of the view with it
    bit for bit (docs/viewer.md §2), where the preset's own window is more than a grey level away; Ctrl-C stops it
    cleanly."""
    import signal
    import subprocess
    import sys
    import urllib.error
    import urllib.request

    from test_hardening import sigint_default

    path = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=24), levels=2).threshold(keep=0.2).save(
        tmp_path / "h.clw")
    start = dict(preset=None, centre=0.0, width=1.0, opacity=1.0)  # the page's editor at its start

    async def shaded(url):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(url.replace("/?", "/ws?"))
            hello = await ws.receive_json()
            await ws.send_str(json.dumps(dict(BASE, seq=1, mode="shaded", tf=start, azimuth=50.0)))
            return hello, await frames_until_final(ws, 1)
    with subprocess.Popen([sys.executable, "-m", "clwave", "view", str(path), "--size", "32", "--tf", "hydrogen",
                           "--tf-window", "0.1,0.8"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                          text=True, preexec_fn=sigint_default) as proc:
        try:
            line = proc.stdout.readline()
            assert line.startswith("clwave view: open http://127.0.0.1:"), line
            url = line.split()[-1]
            assert urllib.request.urlopen(url, timeout=30).status == 200
            with pytest.raises(urllib.error.HTTPError, match="403") as refused:
                urllib.request.urlopen(url.split("?")[0], timeout=30)
            refused.value.close()
            hello, frames = run(shaded(url))
            proc.send_signal(signal.SIGINT)
            assert proc.wait(timeout=30) == 0
            assert "stopped" in proc.stderr.read()
        finally:
            proc.kill()
    assert hello["tf"] == dict(name="hydrogen", window=[0.1, 0.8])
    assert all(f["tf_window"] == [0.1, 0.8] for f, _ in frames) and frames[-1][0]["final"]
    got, camera = decode(frames[-1][1]).astype(int), clwave.Camera(50.0, 20.0, 32, extent=frames[-1][0]["extent"])
    expect, other = (clwave.raytrace(clwave.WaveletVolume.open(path), camera, tolerance=1e-2, transfer_function=clwave.
                                     TransferFunction.preset("hydrogen", window=window)).to_uint8(background=(0, 0, 0))
                     for window in ((0.1, 0.8), None))
    assert expect.std() > 5 and np.array_equal(got, expect) and np.abs(got - other).max() > 1


def test_loopback_names():
    """This machine's loopback in every spelling a Host header may carry (review21: ``localhost.`` and an IPv4-mapped
    127.0.0.1 were refused with 403), and nothing else."""
    from clwave.view.address import host_name, is_loopback

    assert all(map(is_loopback, ("127.0.0.1", "localhost", "localhost.", "::1", "127.1.2.3", "::ffff:127.0.0.1")))
    assert not any(map(is_loopback, ("0.0.0.0", "192.168.1.4", "::", "example.org", "localhost..", "::ffff:10.0.0.1",
                                     "localhost.example.org")))
    assert [host_name(h) for h in ("localhost.:8080", "[::ffff:127.0.0.1]:80", "LOCALHOST")] == \
        ["localhost.", "::ffff:127.0.0.1", "localhost"]


def test_a_transfer_function_chosen_opens_the_page_in_the_shaded_mode(viewer):
    """trial26 finding 11: `clwave view X --tf F` opened in X-ray mode, where a user who gave a transfer function
    expects its shaded view (docs/viewer.md: "shaded through ct-bone from the first frame").  The hello's ``mode``, the
    mode the page opens in: shaded where a transfer function was chosen (given, tf=; or the model's own: a volume
    classified with it, pre or post), X-ray otherwise (grey is no one's choice)."""
    async def hello_of(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(socket_url(v))
            return await ws.receive_json()

    assert run(hello_of(viewer))["mode"] == "xray"
    vol = clwave.phantom("hydrogen", n=16)
    scalar = clwave.WaveletVolume.from_volume(vol, levels=1).threshold(keep=0.2)
    for model, options in ((scalar, dict(tf="hydrogen")), (vol, dict(tf="hydrogen")),
                           (vol, dict(tf="hydrogen", classify="post")), (scalar, {}),
                           (np.stack([vol.data] * 4, axis=-1), {})):
        with view(model, size=16, keep=0.2, **options) as v:
            hello = run(hello_of(v))
        assert hello["mode"] == ("shaded" if options else "xray") and hello["mode"] in hello["modes"], options
