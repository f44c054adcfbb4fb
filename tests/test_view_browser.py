"""The viewer's page in a real headless browser (Debian's chromium through Selenium; docs/viewer.md §6):
first image, orbit by dragging, the final X-ray frame against clwave.splat, a wrong token, two tabs, superseded
frames, a hostile socket beside a working page, the transfer-function editor's presets, sliders, points and undo, the
X-ray colour bar."""

import io
import sys
from pathlib import Path

import numpy as np
import pytest

import clwave
from clwave.model.geometry import view_frame
from clwave.view import prefix as view_prefix
from clwave.view import view
from clwave.view.prefix import PrefixFirst
import test_view_prefix

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
import browser  # noqa: E402  (tools/browser.py)

pytestmark = pytest.mark.skipif(browser.executables() is None, reason=browser.SETUP)
SIZE = (64, 80)
clw = test_view_prefix.clw  # the fixture: hydrogen 40^3 RGBA, 12,800 coefficients in the file


#: the scalar model's transfer function (classified while rendering), where the page's editor starts
START = clwave.TransferFunction.preset("hydrogen", window=(0.1, 0.8))


@pytest.fixture(scope="module")
def viewer():
    with view(clwave.phantom("hydrogen", n=40), size=SIZE, keep=0.2, tf=START, classify="post") as v:
        yield v


@pytest.fixture(scope="module")
def page():
    with browser.chromium() as driver:
        yield driver


def decode(data):
    import imageio.v3 as iio
    return iio.imread(io.BytesIO(data))


def open_xray(page, url):
    """The page of the module's viewer, which opens shaded (its model has a transfer function), in the X-ray mode."""
    browser.open_viewer(page, url)
    page.execute_script('document.querySelector(\'input[value="xray"]\').click();')
    browser.wait_for(page, "const c = window.clwave.current(); return c.fig.mode === 'xray' && c.fig")


def test_drag_orbits_and_the_still_view_refines_to_the_splat(viewer, page):
    open_xray(page, viewer.url)
    browser.wait_final(page)
    start, data0 = browser.current_frame(page)
    browser.drag(page, 60, 24, steps=8, pause=0.05)  # held: the frames while moving
    moving = browser.wait_for(page, f"const f = window.clwave.current().fig; return f.seq > {start['seq']} && f")
    assert not moving["final"] and moving["mime"] == "image/jpeg"
    browser.release(page)
    final = browser.wait_final(page)
    state = page.execute_script("return window.clwave.state")
    # dragging right turns the volume right (azimuth down), dragging down looks from above (elevation up)
    assert final["azimuth"] == pytest.approx(state["azimuth"]) and (final["azimuth"] - 30) % 360 > 180
    assert final["elevation"] == pytest.approx(state["elevation"]) and final["elevation"] > 20
    figures, data = browser.current_frame(page)
    got = decode(data)
    assert figures["mime"] == "image/png" and got.shape == SIZE and np.any(got != decode(data0))
    camera = clwave.Camera(final["azimuth"], final["elevation"], SIZE, extent=final["extent"])
    expect = clwave.splat(viewer.server.wv, camera).to_uint8(tuple(final["window"]))
    assert expect.std() > 10 and np.abs(got.astype(int) - expect).max() <= 1
    stats = page.execute_script("return window.clwave.stats")
    assert stats["frames"][-1]["seq"] == final["seq"] and stats["shown"] > 2


def test_a_wrong_token_gets_403(viewer, page):
    page.get(viewer.url[:-2] + "xx")
    assert "403" in page.find_element("tag name", "body").text
    page.get(viewer.url.split("?")[0])
    assert "403" in page.find_element("tag name", "body").text


def test_two_tabs_orbit_independently(viewer, page):
    open_xray(page, viewer.url)
    first = page.current_window_handle
    page.switch_to.new_window("tab")
    open_xray(page, viewer.url)
    second = page.current_window_handle
    browser.drag(page, -40, 0, steps=4, hold=False)
    turned = browser.wait_final(page)
    page.switch_to.window(first)
    browser.drag(page, 0, -30, steps=4, hold=False)
    tilted = browser.wait_final(page)
    assert turned["azimuth"] > 30 and turned["elevation"] == 20
    assert tilted["azimuth"] == 30 and tilted["elevation"] < 20
    page.switch_to.window(second)
    assert page.execute_script("return window.clwave.current().fig")["azimuth"] == turned["azimuth"]
    page.close()
    page.switch_to.window(first)


def test_superseded_frames_are_dropped(viewer, page):
    """Views sent faster than they render: the page shows only frames of its latest view, and the server
    abandons the others (fewer frames arrive than views were sent)."""
    open_xray(page, viewer.url)
    page.execute_script("const c = window.clwave; for (let i = 1; i <= 20; i++) "
                        "setTimeout(() => { c.state.azimuth = 30 + 3 * i; c.send(); }, 5 * i);")
    final = browser.wait_for(page, "const c = window.clwave.current(); return c && c.fig.final && "
                                   "c.fig.azimuth === 90 && c.fig")
    stats = page.execute_script("return window.clwave.stats")
    seqs = [f["seq"] for f in stats["frames"]]
    assert seqs == sorted(seqs) and seqs[-1] == final["seq"]  # never a frame of an earlier view after a later
    views = final["seq"] - 1  # the page's first view, then one per change
    assert stats["received"] < views * 6  # a still view has up to 6 frames; most views' were never rendered


def test_a_hostile_socket_closes_and_the_page_keeps_working(viewer, page):
    open_xray(page, viewer.url)
    code = page.execute_async_script(
        "const done = arguments[arguments.length - 1];"
        "const ws = new WebSocket(`ws://${location.host}/ws${location.search}`);"
        "ws.onopen = () => ws.send(JSON.stringify({type: 'view', seq: 1, command: 'rm -rf /'}));"
        "ws.onclose = (ev) => done(ev.code);")
    assert code == 1008
    before = browser.shown(page)
    browser.drag(page, 30, 0, steps=3, hold=False)
    assert browser.wait_final(page)["azimuth"] != 30 and browser.shown(page) > before


def test_a_given_transfer_function_opens_shaded_with_the_editor_over_the_values_whole_range(viewer, page):
    """trial26 finding 11: `clwave view X --tf F` opened in X-ray mode, and the editor's histogram looked like the
    window's alone (a window that nearly spans the data).  Given a transfer function, the page opens shaded (its radio
    checked, the shaded controls enabled, the first final frame shaded), and the editor names the values its canvas
    spans: the input's whole range (the model's value_range, wider than the window 0.1 … 0.8), histogram behind."""
    browser.open_viewer(page, viewer.url)
    first = browser.wait_final(page)
    checked, xray_off, shaded_off = page.execute_script(
        'return [document.querySelector(\'input[value="shaded"]\').checked, '
        'document.getElementById("xray-controls").disabled, document.getElementById("shaded-controls").disabled]')
    assert first["mode"] == "shaded" and checked and xray_off and not shaded_off
    lo, hi = viewer.server.wv.value_range
    axis = browser.wait_for(page, 'const t = document.getElementById("tf-axis").textContent; '
                                  'return t.includes("…") && t')
    np.testing.assert_allclose([float(x) for x in axis.split(" … ")], [lo, hi], rtol=1e-3)
    assert lo < 0.1 and hi > 0.8


def test_shaded_with_the_transfer_function_editor(viewer, page):
    """A scalar model in the shaded mode: the editor starts from the model's transfer function (its preset and window
    shown) and the first still view's final frame is clwave.raytrace with it; then a preset chosen and
    the opacity slider moved show a cheaper frame of the new function at once; let go, the final frame is
    clwave.raytrace of the view with that function (made here from the preset)."""
    browser.open_viewer(page, viewer.url)
    page.execute_script('document.querySelector(\'input[value="shaded"]\').click();')
    start = browser.wait_final(page)
    shown = page.execute_script('const p = document.getElementById("tf-preset"); return [p.value, '
                                'p.selectedOptions[0].textContent, document.getElementById("tf-range").textContent]')
    assert shown == ["", "hydrogen, window 0.1 … 0.8 (start)", "0.1 … 0.8"] and start["tf_window"] == [0.1, 0.8]
    camera = clwave.Camera(start["azimuth"], start["elevation"], SIZE, extent=start["extent"])
    expect = clwave.raytrace(viewer.server.wv, camera, tolerance=1e-2, transfer_function=START).to_uint8(
        background=(0.0, 0.0, 0.0))
    assert expect.std() > 5 and np.array_equal(decode(browser.current_frame(page)[1]), expect)
    page.execute_script('const p = document.getElementById("tf-preset"); p.value = "hydrogen";'
                        'p.dispatchEvent(new Event("change"));')
    browser.wait_for(page, "const f = window.clwave.current().fig; return f.final && f.tf_window[0] === 0 && f")
    assert page.execute_script('return document.getElementById("tf-range").textContent') == "0 … 1"
    seq = page.execute_script("const e = document.getElementById('tf-opacity'); e.value = 75;"
                              "e.dispatchEvent(new Event('input')); return window.clwave.current().fig.seq")
    moving = browser.wait_for(page, f"const f = window.clwave.current().fig; return f.seq > {seq} && f")
    assert moving["mode"] == "shaded" and not moving["final"] and moving["width"] < SIZE[1]
    page.execute_script("document.getElementById('tf-opacity').dispatchEvent(new Event('change'))")
    final = browser.wait_final(page)
    points = clwave.TransferFunction.preset("hydrogen").points.copy()
    points[:, 4] *= 10.0  # the slider at 75: 10^((75 - 50) / 25)
    camera = clwave.Camera(final["azimuth"], final["elevation"], SIZE, extent=final["extent"])
    expect = clwave.raytrace(viewer.server.wv, camera, tolerance=1e-2, transfer_function=clwave.TransferFunction(
        points, window=(0.0, 1.0))).to_uint8(background=(0.0, 0.0, 0.0))
    figures, data = browser.current_frame(page)
    assert figures["tolerance"] == 1e-2 and expect.std() > 5
    assert np.abs(decode(data).astype(int) - expect).max() <= 1


def test_a_crop_slider_clips_the_shaded_view_and_a_plane_that_keeps_nothing_is_said(viewer, page):
    """The clip controls (a scalar model, shaded): the y crop's high slider moved shows a cheaper frame at once; let
    go, the final frame is clwave.raytrace of the view clipped to that box (the hello's content box, its y end moved)
    bit for bit, another image than the unclipped one, and the status line says "refined"; "copy as Python" writes
    the box.  The plane ticked faces the camera through the box's centre (its normal the view's direction) and clips
    the final frame as clwave.raytrace does.  A plane keeping x above the box's end keeps nothing: the Clip's line on
    the status line, which "uncut" clears (the tab goes on, the unclipped image again).  A box thinner than a pixel:
    the renderer's warning that no ray meets the content on the status line."""
    browser.open_viewer(page, viewer.url)
    page.execute_script('document.querySelector(\'input[value="shaded"]\').click();')
    start = browser.wait_final(page)
    whole = decode(browser.current_frame(page)[1])
    page.execute_script("const e = document.getElementById('clip-y1'); e.value = 500;"
                        "e.dispatchEvent(new Event('input'))")
    moving = browser.wait_for(page, f"const f = window.clwave.current().fig; return f.seq > {start['seq']} && f")
    assert not moving["final"] and moving["width"] < SIZE[1]
    page.execute_script("document.getElementById('clip-y1').dispatchEvent(new Event('change'))")
    final, got = latest_final(page, moving)
    assert page.execute_script("return document.getElementById('status').textContent") == "refined"
    lo, hi = viewer.server.model()["box"]
    clip = clwave.Clip(lo=lo, hi=(hi[0], lo[1] + (hi[1] - lo[1]) * 500 / 1000, hi[2]))
    camera = clwave.Camera(final["azimuth"], final["elevation"], SIZE, extent=final["extent"])
    expect = clwave.raytrace(viewer.server.wv, camera, tolerance=1e-2, transfer_function=START, clip=clip).to_uint8(
        background=(0.0, 0.0, 0.0))
    assert expect.std() > 5 and np.array_equal(got, expect) and np.abs(got.astype(int) - whole).max() > 20
    page.find_element("id", "copy-python").click()
    text = browser.wait_for(page, "const e = window.clwave.stats.exported; return e && e.kind === 'python' && e.text")
    assert f"clip = clwave.Clip(lo=({lo[0]!r}, " in text and ", clip=clip)" in text
    page.execute_script("document.getElementById('clip-plane').click()")  # facing the camera, through the centre
    final, got = latest_final(page, final)
    sent = page.execute_script("return window.clwave.view().clip")
    (plane,) = sent["planes"]
    n, _, _ = view_frame(final["azimuth"], final["elevation"])
    assert plane[:3] == pytest.approx((np.array(lo) + hi) / 2, abs=1e-12) and plane[3:] == pytest.approx(-n, abs=1e-12)
    expect = clwave.raytrace(viewer.server.wv, camera, tolerance=1e-2, transfer_function=START, clip=clwave.Clip(
        lo=sent["box"][:3], hi=sent["box"][3:], planes=[(plane[:3], plane[3:])])).to_uint8(background=(0.0, 0.0, 0.0))
    assert expect.std() > 5 and np.array_equal(got, expect)
    page.execute_script("const a = document.getElementById('clip-axis'), at = document.getElementById('clip-at');"
                        "a.value = '+x'; at.value = 1000; a.dispatchEvent(new Event('change'))")
    line = browser.wait_for(page, "const s = document.getElementById('status');"
                                  "return s.classList.contains('error') && s.textContent")
    assert "keeps nothing (no volume lies inside all of it)" in line and "\n" not in line
    page.find_element("id", "clip-reset").click()
    browser.wait_for(page, "const s = document.getElementById('status');"
                           "return !s.classList.contains('error') && s.textContent === 'refined'")
    assert np.array_equal(decode(browser.current_frame(page)[1]), whole)
    # a box thinner than a pixel round the centre: no ray meets the content, and the status line says the renderer's
    # warning over the blank final frame (until notes28 "refined", the warning on the server's stderr)
    seq = page.execute_script("return window.clwave.current().fig.seq")
    page.execute_script("for (const a of ['x', 'y', 'z']) { document.getElementById(`clip-${a}1`).value = 501;"
                        "document.getElementById(`clip-${a}0`).value = 500; }"
                        "document.getElementById('clip-z0').dispatchEvent(new Event('change'))")
    line = browser.wait_for(page, f"const f = window.clwave.current().fig; return f.seq > {seq} && f.final && "
                                  "!window.clwave.state.moving && document.getElementById('status').textContent")
    assert "no ray met the model's content" in line and "a clip cuts it away" in line
    assert not decode(browser.current_frame(page)[1]).any()


def latest_final(page, after):
    """The figures of the final frame of the page's latest view, a view after the frame ``after``; its picture."""
    browser.wait_for(page, f"const c = window.clwave.current(); return c && c.fig.seq > {after['seq']}")
    return browser.wait_final(page), decode(browser.current_frame(page)[1])


def test_the_editor_and_the_sliders_act_on_the_same_points_and_undo(viewer, page):
    """The transfer-function editor (a scalar model, shaded) from the start function: the width slider dragged (three
    steps) widens the start's window 10^0.5 times; a press on the canvas where there is no point adds one, dragging
    moves it (drag frames of the edited function meanwhile); let go, the page's points are the widened start's and the
    new one, and the final frame, another image than before, is clwave.raytrace of the view with
    TransferFunction(those points).  The width slider back at its middle narrows all of them back about the window's
    middle: the start's points where they began (the final frame clwave.raytrace of them).  Ctrl+Z undoes that drag
    (the frame before it, pixel for pixel); a double-click on the point removes it, the undo button brings it back,
    Ctrl+Shift+Z removes it again."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.keys import Keys

    def keys(*held, key):
        chain = ActionChains(page)
        for k in held:
            chain.key_down(k)
        chain.send_keys(key)
        for k in held:
            chain.key_up(k)
        chain.perform()

    def width(*values):  # the width slider dragged through these positions, then let go
        page.execute_script("const e = document.getElementById('tf-width'); for (const v of arguments[0]) { "
                            "e.value = v; e.dispatchEvent(new Event('input')); } e.dispatchEvent(new Event('change'))",
                            values)

    def raytrace(fig, points):
        camera = clwave.Camera(fig["azimuth"], fig["elevation"], SIZE, extent=fig["extent"])
        return clwave.raytrace(viewer.server.wv, camera, tolerance=1e-2, transfer_function=clwave.TransferFunction(
            points)).to_uint8(background=(0.0, 0.0, 0.0))

    browser.open_viewer(page, viewer.url)
    page.execute_script('document.querySelector(\'input[value="shaded"]\').click();')
    start = browser.wait_final(page)
    assert start["tf_points"] == np.column_stack([START.data_points(), START.points[:, 1:]]).tolist()
    width(60, 70, 75)
    wide, before = latest_final(page, start)
    mid, k = sum(start["tf_window"]) / 2, 10 ** 0.5
    widened = np.array(start["tf_points"])
    widened[:, 0] = mid + (widened[:, 0] - mid) * k
    np.testing.assert_allclose(wide["tf_points"], widened, rtol=1e-12)
    editor = page.find_element("id", "tf-editor")
    page.execute_script("arguments[0].scrollIntoView({block: 'center'})", editor)
    ActionChains(page, duration=0).move_to_element_with_offset(editor, 30, -25).click_and_hold().move_by_offset(
        8, -4).pause(0.2).move_by_offset(8, -4).perform()  # held: from a spot with no point, up to 0.8 of the axis
    moving = browser.wait_for(page, f"const f = window.clwave.current().fig; return f.seq > {wide['seq']} && "
                                    f"f.tf_points.length === {len(START.points) + 1} && f")
    assert not moving["final"] and moving["mime"] == "image/jpeg"
    browser.release(page)
    final = browser.wait_final(page)
    points = page.execute_script("return window.clwave.state.tf.points")
    new = [i for i, p in enumerate(points) if not np.isclose(p[0], widened[:, 0]).any()]
    assert len(new) == 1 and final["tf_points"] == points  # the page's values, as the server got them
    np.testing.assert_allclose(np.delete(points, new, axis=0), widened, rtol=1e-9)
    got = decode(browser.current_frame(page)[1])
    assert np.array_equal(got, raytrace(final, points)) and np.abs(got.astype(int) - before).max() > 1

    width(60, 50)  # the edited points narrowed back about the window's middle: the start's where they began
    narrow, picture = latest_final(page, final)
    sent = page.execute_script("return window.clwave.state.tf.points")
    expect = np.array(points)
    expect[:, 0] = mid + (expect[:, 0] - mid) / k
    np.testing.assert_allclose(sent, expect, rtol=1e-9)
    np.testing.assert_allclose(np.delete(sent, new, axis=0), start["tf_points"], rtol=1e-9)
    assert narrow["tf_points"] == sent and np.array_equal(picture, raytrace(narrow, sent))

    keys(Keys.CONTROL, key="z")  # the slider's drag, one step
    undone, picture = latest_final(page, narrow)
    assert undone["tf_points"] == points and np.array_equal(picture, got)
    ActionChains(page, duration=0).double_click().perform()  # on the point, where the drag left it: removed
    removed, without = latest_final(page, undone)
    assert len(removed["tf_points"]) == len(START.points)
    page.find_element("id", "tf-undo").click()
    back, picture = latest_final(page, removed)
    assert back["tf_points"] == points and np.array_equal(picture, got)
    keys(Keys.CONTROL, Keys.SHIFT, key="z")
    again, picture = latest_final(page, back)
    assert again["tf_points"] == removed["tf_points"] and np.array_equal(picture, without)


def test_the_colour_bar_shows_the_map_over_the_window(viewer, page):
    """X-ray views in inferno: the bar under the image is the table's 256 rows, labelled with the window's low,
    middle and high values (three digits), which follow the window's sliders and the auto window."""
    from clwave.view.colours import table

    open_xray(page, viewer.url)
    page.execute_script("const m = document.getElementById('colour-map'); m.value = 'inferno';"
                        "m.dispatchEvent(new Event('change'));"
                        "const e = document.getElementById('hi'); e.value = 300; e.dispatchEvent(new Event('input'));")
    final = browser.wait_for(page, "const c = window.clwave.current(); return c.fig.colour_map === 'inferno' && "
                                   "c.fig.final && c.fig.seq === window.clwave.latest() && c.fig")
    bar = page.execute_script("return Array.from(document.getElementById('colour-bar').getContext('2d')"
                              ".getImageData(0, 0, 256, 1).data)")
    np.testing.assert_array_equal(np.reshape(bar, (256, 4))[:, :3], table("inferno"))

    def labels():  # under an image narrower than 200 px (80 here) the middle label is hidden, its text kept
        return [float(page.find_element("id", name).get_attribute("textContent")) for name in
                ("bar-lo", "bar-mid", "bar-hi")]
    assert page.find_element("id", "colour-bar").is_displayed()
    assert not page.find_element("id", "bar-mid").is_displayed()
    lo, hi = final["window"]
    np.testing.assert_allclose(labels(), [lo, (lo + hi) / 2, hi], rtol=5e-3)
    page.find_element("id", "auto-window").click()
    auto = browser.wait_final(page)
    lo, hi = page.execute_script("return window.clwave.state.window") or viewer.server.sources["xray"].auto_window
    assert auto["window"] == [lo, hi] and hi > final["window"][1] * 1.01
    np.testing.assert_allclose(labels(), [lo, (lo + hi) / 2, hi], rtol=5e-3)


def test_a_tab_past_the_most_is_told_what_to_do(viewer, page, monkeypatch):
    """A page whose socket the server refuses for having as many tabs as it serves (here none: MAX_TABS 0) says so
    with the server's line, not that the server has gone, and its sending controls are disabled."""
    from clwave.view import server as view_server

    monkeypatch.setattr(view_server, "MAX_TABS", 0)
    page.get(viewer.url)
    status = browser.wait_for(page, "const s = document.getElementById('status'); "
                                    "return s.classList.contains('error') && s.textContent", timeout=30)
    assert status == "not connected (1013: 0 tabs have this viewer open already: close one, then reload this page)"
    assert page.execute_script("return document.getElementById('mode').disabled")


def test_the_colour_bars_labels_never_run_together(page):
    """Line integrals in the thousands, below 0 too, under a 96 px image: the labels ran together
    ("-1883.12e+36.43e+3"); they are short (no "+", no trailing zeros), the middle one hidden under 200 px, and the
    high one wraps below the low one where the two do not fit side by side."""
    vol = clwave.phantom("hydrogen", n=24)
    scaled = clwave.Volume(vol.data * 3e4 - 600.0, spacing=vol.spacing)
    with view(scaled, size=96, keep=0.2) as v:
        browser.open_viewer(page, v.url)
        page.execute_script("const m = document.getElementById('colour-map'); m.value = 'inferno';"
                            "m.dispatchEvent(new Event('change'));")
        browser.wait_for(page, "const c = window.clwave.current(); return c.fig.colour_map === 'inferno' && "
                               "c.fig.final && c.fig")
        shown = page.execute_script("return ['bar-lo', 'bar-mid', 'bar-hi'].map((id) => document.getElementById(id))"
                                    ".filter((e) => !e.hidden).map((e) => [e.textContent, "
                                    "e.getBoundingClientRect().toJSON()])")
        lo, hi = v.server.sources["xray"].auto_window
    assert [text for text, _ in shown] == [page_number(lo), page_number(hi)] and lo < -100 and hi > 1000, shown
    assert all("+" not in text and len(text) <= 7 for text, _ in shown)
    (_, a), (_, b) = shown
    assert a["right"] <= b["left"] or a["bottom"] <= b["top"], shown


def page_number(x) -> str:
    """The colour bar's label of ``x`` (at least 1e-6 in magnitude, where JavaScript's toPrecision and Python's "g"
    agree but for the exponent's form) as the page writes it: three digits, no "+", no trailing zeros."""
    return f"{x:.3g}".replace("e+0", "e").replace("e-0", "e-").replace("e+", "e")


def test_a_stopped_server_disables_the_pages_controls_and_leaves_its_last_image(page):
    """The server stops under an open page: the status line says so and what to do, every control that sends is
    disabled (the mode, the X-ray and the shaded boxes), a drag, the wheel and a double-click on the image change
    nothing, and the last image stays, still to be saved.  The server started again on the same port: the page
    reloaded at its old address is refused (a new token, 403), the new address works."""
    from selenium.webdriver.common.action_chains import ActionChains

    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=16), levels=1).threshold(keep=0.6)
    image = "return document.getElementById('image').toDataURL()"
    with view(wv, size=SIZE) as v:
        browser.open_viewer(page, v.url)
        browser.wait_final(page)
        before, port = page.execute_script(image), v.server.port
    status = browser.wait_for(page, "const s = document.getElementById('status'); "
                                    "return s.classList.contains('error') && s.textContent", timeout=30)
    assert status == ("disconnected: the viewer's server has stopped or cannot be reached (1001: the viewer stopped); "
                      "restart clwave view … (or clwave.view) and open the address it prints, whose token is new. "
                      "This image is the last it sent.")
    sending = ", ".join(f"#{box} {kind}" for box in ("mode", "camera-controls", "xray-controls", "shaded-controls",
                                                     "export") for kind in ("input", "select", "button"))
    controls = page.execute_script(f"return Array.from(document.querySelectorAll('{sending}'))"
                                   ".map(e => e.matches(':disabled'))")
    # 2 modes, 10 camera controls (six standard views, the scale bar's and the orientation letters' too), 5 X-ray
    # ones, 9 shaded ones and 10 of the clip (6 crop sliders, the plane's box, list and slider, "uncut"), 4 of the
    # export's (the size, save, two copies)
    assert len(controls) == 40 and all(controls)
    state, shown = page.execute_script("return JSON.stringify(window.clwave.state)"), browser.shown(page)
    browser.drag(page, 30, 10, steps=3, hold=False)
    ActionChains(page).scroll_to_element(page.find_element("id", "image")).double_click(
        page.find_element("id", "image")).perform()
    page.execute_script("document.getElementById('image').dispatchEvent(new WheelEvent('wheel', {deltaY: -300}))")
    assert page.execute_script("return JSON.stringify(window.clwave.state)") == state and browser.shown(page) == shown
    assert page.execute_script(image) == before and page.find_element("id", "save").is_enabled()
    with view(wv, size=SIZE, port=port) as again:
        page.refresh()
        assert "403" in page.find_element("tag name", "body").text
        assert browser.open_viewer(page, again.url) > 0


def test_a_files_rest_that_cannot_be_read_is_said_on_the_model_line(clw, page, monkeypatch):
    """A ``.clw`` file served from its prefix whose rest fails to read: the page's model line says that the view holds
    the file's most important coefficients only, and why (the ``model`` message's ``failure``), not "kept"."""
    monkeypatch.setattr(view_prefix, "PREFIX", 2048)
    monkeypatch.setattr(PrefixFirst, "whole", lambda self, **k: (_ for _ in ()).throw(
        clwave.FileFormatError("damaged past its prefix")))
    with view(clw, size=SIZE) as v:
        browser.open_viewer(page, v.url)
        line = browser.wait_for(page, "const m = document.getElementById('model').textContent; "
                                      "return !m.includes('reading') && m")
    assert line == ("40 × 40 × 40 voxels, 4 channel(s), cubic, 2,048 coefficients (the file's most important only: "
                    "the rest could not be read, damaged past its prefix). The model's error against the input: not "
                    "recorded in the file (clwave compress records it where it reads the input whole); the frames' "
                    "error is against the model's final image")


def test_the_view_is_copied_as_a_command_and_as_python_and_saved_at_twice_its_size(page, tmp_path):
    """A .clw file's page in perspective: "copy as command" and "copy as Python" show the server's text of the view in
    the box, selected (headless chromium has no clipboard permission: the page says Ctrl+C copies it); "save image"
    at 1x is the final frame (within a grey level: the page's frame is accumulated pass by pass,
    tests/test_view_export.py; its orientation letters unticked: a saved image holds those shown) and at 2x twice its
    size, the server's image of that view bit for bit."""
    import asyncio
    import json

    import aiohttp

    path = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=24), levels=2).threshold(keep=0.2).save(
        tmp_path / "h.clw")
    with view(str(path), size=SIZE) as v:
        browser.open_viewer(page, v.url)
        browser.wait_final(page)
        page.find_element("id", "perspective").click()
        page.find_element("id", "edge-labels").click()
        browser.wait_for(page, "return window.clwave.state.fov === 30 && !window.clwave.state.edge_labels && "
                               "document.getElementById('edge-left').hidden")
        browser.wait_final(page)
        page.find_element("id", "copy-command").click()
        shown = browser.wait_for(page, "const e = window.clwave.stats.exported; return e && e.kind === 'command' && e")
        box = page.execute_script("const b = document.getElementById('export-text'); return [b.value, "
                                  "b.selectionStart, b.selectionEnd, "
                                  "document.getElementById('export-note').textContent]")
        page.find_element("id", "copy-python").click()
        code = browser.wait_for(page, "const e = window.clwave.stats.exported; return e && e.kind === 'python' && e")
        page.save_screenshot(str(tmp_path / "export.png"))
        page.find_element("id", "save-image").click()
        one = browser.wait_for(page, "return window.clwave.stats.saved")
        one_png = blob(page)
        final, frame = browser.current_frame(page)
        page.execute_script("const s = document.getElementById('export-scale'); s.value = '2';")
        page.execute_script("window.clwave.stats.saved = null")
        page.find_element("id", "save-image").click()
        two = browser.wait_for(page, "return window.clwave.stats.saved")
        two_png = blob(page)
        state = page.execute_script("return window.clwave.state")

        async def server_image():
            async with aiohttp.ClientSession() as s:
                body = json.dumps(dict(view=dict(state, type="view", seq=1, moving=False), size=[128, 160]))
                async with s.post(v.url.replace("/?", "/image?"), data=body) as r:
                    return await r.read()
        expect = decode(asyncio.run(server_image()))
    text = shown["text"]
    assert text.startswith(f"clwave render {path} --method splat --azimuth 30.0 --elevation 20.0 --perspective "
                           f"--fov 30.0 --distance ")
    window = ",".join(map(repr, final["window"]))  # "--window=-1.0,2.0": argparse takes "-1.0,2.0" for an option
    assert text.endswith(f"--size 64x80 --window{'=' if window.startswith('-') else ' '}{window} -o view.png")
    assert box[0] == text and box[1:3] == [0, len(text)]
    assert box[3] in ("copied the command line", "the command line is selected: Ctrl+C copies it")
    assert f"wv = clwave.WaveletVolume.open({str(path)!r})" in code["text"]
    assert "perspective=True, fov=30.0" in code["text"]
    assert one["size"] == [64, 80] and two["size"] == [128, 160]
    got = decode(one_png).astype(int)
    assert got.shape[:2] == (64, 80) and np.abs(got - decode(frame)).max() <= 1
    assert np.array_equal(decode(two_png), expect) and expect.shape[:2] == (128, 160) and expect.std() > 5


def blob(page) -> bytes:
    """The bytes of the image the page saved last."""
    import base64

    url = page.execute_async_script(
        "const done = arguments[arguments.length - 1], r = new FileReader(); r.onload = () => done(r.result);"
        "r.readAsDataURL(window.clwave.stats.saved.blob);")
    return base64.b64decode(url.split(",", 1)[1])


def test_the_scale_bar_box_draws_the_bar_over_an_orthographic_view(viewer, page, tmp_path):
    """Ticked, the overlay holds the frame's bar, round(length / pixel) white pixels in a row over the image's bottom
    right, and the Python of the view says scale_bar=True; zoomed, the bar follows the new extent; in perspective the
    box is disabled and the overlay empty."""
    overlay = ("const o = document.getElementById('scale-bar-overlay'), d = o.getContext('2d')"
               ".getImageData(0, 0, o.width, o.height).data; return Array.from(d)")

    def longest_white():
        rgba = np.array(page.execute_script(overlay), np.uint8).reshape(*SIZE, 4)
        white = np.all(rgba == 255, axis=-1)
        return max(max((len(run) for run in "".join("1" if w else "0" for w in row).split("0")), default=0)
                   for row in white), np.argwhere(white)

    browser.open_viewer(page, viewer.url)
    browser.wait_final(page)
    assert longest_white()[0] == 0  # unticked: nothing drawn
    page.find_element("id", "scale-bar").click()
    final = browser.wait_final(page)
    length, label = final["scale_bar"]
    run, where = longest_white()
    assert run == round(length / (final["extent"] / SIZE[1])) and label.endswith("units")
    assert where[:, 0].min() > SIZE[0] / 2 and where[:, 1].min() > SIZE[1] / 3
    page.find_element("id", "copy-python").click()
    code = browser.wait_for(page, "const e = window.clwave.stats.exported; return e && e.kind === 'python' && e")
    assert "scale_bar=True, edge_labels={" in code["text"]  # the result carries its unit (trial29 W2); the letters
    page.execute_script("window.clwave.state.zoom = 2.5; window.clwave.send()")
    zoomed = browser.wait_for(page, "const c = window.clwave.current(); return c && c.fig.final && "
                                    "c.fig.extent < " + repr(final["extent"] / 2) + " && c.fig")
    assert longest_white()[0] == round(zoomed["scale_bar"][0] / (zoomed["extent"] / SIZE[1]))
    page.find_element("id", "perspective").click()
    browser.wait_for(page, "const c = window.clwave.current(); return c && c.fig.fov === 30 && c.fig")
    assert page.execute_script("return document.getElementById('scale-bar').disabled && "
                               "!window.clwave.state.scale_bar")
    assert longest_white()[0] == 0


def test_the_pages_state_and_edit_history_survive_a_reload_for_the_same_model_only(viewer, page):
    """The page keeps its view in the address's hash and its edit history in sessionStorage (docs/viewer.md §4): an
    X-ray view turned and zoomed in inferno under a window of its own, then shaded through the start function widened
    and a point added on the editor's canvas; reloaded, the page shows the same view: the shaded final frame the same
    pixels (clwave.raytrace of the page's points), the X-ray one the same window and map, and the undo button takes
    back the point's drag (the frame before it, pixel for pixel).  The same address on another model's viewer applies
    none of it and says so."""
    from selenium.webdriver.common.action_chains import ActionChains

    open_xray(page, viewer.url)
    start = browser.wait_final(page)
    page.execute_script("Object.assign(window.clwave.state, {azimuth: 75, elevation: -35, zoom: 1.4});"
                        "const m = document.getElementById('colour-map'); m.value = 'inferno';"
                        "m.dispatchEvent(new Event('change'));"
                        "const e = document.getElementById('hi'); e.value = 300; e.dispatchEvent(new Event('input'));")
    xray, _ = latest_final(page, start)
    assert xray["colour_map"] == "inferno" and xray["azimuth"] == 75
    page.execute_script('document.querySelector(\'input[value="shaded"]\').click();')
    shaded, _ = latest_final(page, xray)
    page.execute_script("const e = document.getElementById('tf-width'); e.value = 70; e.dispatchEvent(new "
                        "Event('input')); e.dispatchEvent(new Event('change'))")
    wide, before = latest_final(page, shaded)
    editor = page.find_element("id", "tf-editor")
    page.execute_script("arguments[0].scrollIntoView({block: 'center'})", editor)
    ActionChains(page, duration=0).move_to_element_with_offset(editor, 30, -25).click_and_hold().move_by_offset(
        8, -4).release().perform()
    edited, picture = latest_final(page, wide)
    points = page.execute_script("return window.clwave.state.tf.points")
    assert len(points) == len(START.points) + 1 and edited["tf_points"] == points
    assert np.abs(picture.astype(int) - before).max() > 1
    kept = page.execute_script("return [location.hash, window.clwave.state]")

    page.refresh()
    browser.wait_for(page, "return window.clwave && window.clwave.stats.firstImage")
    again = browser.wait_final(page)
    assert page.execute_script("return window.clwave.stats.restored") == "applied"
    assert page.execute_script("return [location.hash, window.clwave.state]") == kept
    assert again["mode"] == "shaded" and again["tf_points"] == points and again["azimuth"] == 75
    assert np.array_equal(decode(browser.current_frame(page)[1]), picture)
    camera = clwave.Camera(75, -35, SIZE, extent=again["extent"])
    assert np.array_equal(picture, clwave.raytrace(viewer.server.wv, camera, tolerance=1e-2, transfer_function=(
        clwave.TransferFunction(points))).to_uint8(background=(0.0, 0.0, 0.0)))
    page.find_element("id", "tf-undo").click()  # the history came back with the view: the point's drag undone
    undone, back = latest_final(page, again)
    assert len(undone["tf_points"]) == len(START.points) and np.array_equal(back, before)
    page.execute_script('document.querySelector(\'input[value="xray"]\').click();')
    shown, _ = latest_final(page, undone)
    assert [shown[k] for k in ("colour_map", "window", "extent", "azimuth")] == [
        xray[k] for k in ("colour_map", "window", "extent", "azimuth")]

    with view(clwave.phantom("hydrogen", n=32), size=SIZE, keep=0.2) as other:  # another model: nothing applied
        page.get(other.url + page.execute_script("return location.hash"))
        browser.wait_for(page, "return window.clwave && window.clwave.stats.firstImage")
        fresh = browser.wait_final(page)
        assert page.execute_script("return window.clwave.stats.restored") == "another model"
        assert (fresh["mode"], fresh["azimuth"], fresh["colour_map"]) == ("xray", 30, "grey")


def test_the_edges_say_which_way_the_patient_faces_and_the_view_buttons_and_keys_turn_to_a_side(page, tmp_path):
    """A .clw of a NIfTI stored PSL: the image's edge labels are the frame's (its camera's, orientation.py) and, at the
    page's start (azimuth 30, elevation 20), "PR", "AL", "S", "I"; zoomed and in perspective, the anterior view's
    button and then the key "l" turn the camera to geometry.VIEWS' angles keeping the zoom and the field of view, the
    edges then the radiological table's; "copy as command" writes that view's angles."""
    from test_view_orientation import NAMED, nifti

    edges = "return ['left', 'right', 'top', 'bottom'].map(e => document.getElementById('edge-' + e).textContent)"
    path = clwave.WaveletVolume.from_volume(clwave.load(nifti(tmp_path / "a.nii", "A")), levels=1).save(
        tmp_path / "a.clw")
    with view(str(path), size=SIZE) as v:
        browser.open_viewer(page, v.url)
        first = browser.wait_final(page)
        assert page.execute_script(edges) == ["PR", "AL", "S", "I"] == [first["orientation"][e] for e in NAMED["left"]]
        assert page.find_element("id", "view-anterior").text == "A"
        page.execute_script("document.getElementById('image').dispatchEvent(new WheelEvent('wheel', {deltaY: -300}))")
        page.find_element("id", "perspective").click()
        browser.wait_for(page, "return window.clwave.state.fov === 30 && !window.clwave.state.moving")
        zoom = page.execute_script("return window.clwave.state.zoom")
        page.find_element("id", "view-anterior").click()
        front = browser.wait_final(page)
        assert (front["azimuth"], front["elevation"], front["fov"]) == (90, 0, 30) and zoom > 1.2
        assert page.execute_script(edges) == list(NAMED["anterior"].values())
        page.find_element("tag name", "body").send_keys("l")
        side = browser.wait_for(page, "const c = window.clwave.current(); return c.fig.final && c.fig.azimuth === 180 "
                                      "&& c.fig.seq === window.clwave.latest() && c.fig")
        assert page.execute_script(edges) == list(NAMED["left"].values())
        assert page.execute_script("return window.clwave.state.zoom") == zoom and side["fov"] == 30
        page.find_element("id", "copy-command").click()
        text = browser.wait_for(page, "const e = window.clwave.stats.exported; return e && e.kind === 'command' && "
                                      "e.text")
    assert " --azimuth 180.0 --elevation 0.0 --perspective " in text


def test_a_slab_opens_on_its_face_and_a_double_click_comes_back_to_it(page):
    """A slab thin along z (test_framing's) opens looking down z (camera.SLAB_VIEWS, the hello's ``home``), where its
    final X-ray frame's lit area (above a tenth of the largest grey level) is 1.4 times or more the old opening's
    (azimuth 30, elevation 20, the slab's edge; the server's frame of that view); orbited, a double-click comes back."""
    from clwave.model.camera import SLAB_VIEWS
    from test_framing import slab

    def lit(png):
        grey = decode(png)[..., 0].astype(float)
        return np.count_nonzero(grey > 0.1 * grey.max())

    with view(clwave.Volume(slab(2)), size=SIZE) as v:
        browser.open_viewer(page, v.url)
        first = browser.wait_final(page)
        assert (first["azimuth"], first["elevation"]) == SLAB_VIEWS[2] == tuple(v.server.hello()["home"].values())
        face = lit(blob_of_canvas(page))
        page.execute_script("Object.assign(window.clwave.state, {azimuth: 30, elevation: 20}); window.clwave.send()")
        edge = browser.wait_final(page)
        assert (edge["azimuth"], edge["elevation"]) == (30, 20)
        assert face >= 1.4 * lit(blob_of_canvas(page))
        page.execute_script("document.getElementById('image').dispatchEvent(new MouseEvent('dblclick'))")
        back = browser.wait_final(page)
        assert (back["azimuth"], back["elevation"]) == SLAB_VIEWS[2]


def blob_of_canvas(page) -> bytes:
    """The PNG of the page's canvas, as shown."""
    import base64

    return base64.b64decode(page.execute_script("return document.getElementById('image').toDataURL()").split(",", 1)[1])
