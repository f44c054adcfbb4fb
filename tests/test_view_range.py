"""The viewer's transfer-function editor over the input's range (docs/viewer.md §4): a model ringing past its 8-bit
input, its histogram over 0 .. 255, the window centre's slider in data units kept within it, and the page saying what
the frames' error measures; in a real headless browser (tools/browser.py)."""

import io
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import clwave
from clwave.view import view

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
import browser  # noqa: E402  (tools/browser.py)
from test_value_range import shell  # noqa: E402

pytestmark = pytest.mark.skipif(browser.executables() is None, reason=browser.SETUP)
SIZE = (48, 56)
ABOVE = clwave.TransferFunction.preset("grey", window=(256.7, 316.5))  # the foam's window, above its input's 255


def test_a_window_above_the_input_draws_nothing_and_the_centre_stays_in_the_range(tmp_path):
    import imageio.v3 as iio

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # 5 % drops part of the approximation band: the ringing wanted here
        wv = clwave.WaveletVolume.from_volume(shell(), levels=2).threshold(keep=0.05)
    with view(wv, size=SIZE, tf=ABOVE) as v, browser.chromium() as page:
        browser.open_viewer(page, v.url)
        page.execute_script('document.querySelector(\'input[value="shaded"]\').click();')
        first = browser.wait_final(page)
        assert first["tf_window"] == [256.7, 316.5] and first["note"]  # said why it is blank
        assert not iio.imread(io.BytesIO(browser.current_frame(page)[1])).any()  # the background, exactly
        hist = v.server.sources["shaded"].histogram()
        assert hist["range"] == [0.0, 255.0] and hist["input"] and hist["field"][1] > 300
        slider = browser.wait_for(page, "const e = document.getElementById('tf-window'); return e.max === '255' && "
                                        "[+e.min, +e.max, +e.value, document.getElementById('tf-window-out')"
                                        ".textContent]")
        assert slider == [0, 255, 255, "286.6"]  # the window's centre, shown as it is, the slider at the range's end
        table = page.execute_script("return document.getElementById('figures').textContent")
        model = page.execute_script("return document.getElementById('model').textContent")
        assert "frame's error" not in table or "against the model's final image" in table
        field = " … ".join(f"{x:.4g}" for x in hist["field"])  # the model's at voxel centres (the editor's sample)
        assert f"Input values 0 … 255; the model's field {field}, classified clamped to the input's" in model
        assert "The model's error against the input: not known" in model
        page.save_screenshot(str(tmp_path / "above.png"))

        page.execute_script("const e = document.getElementById('tf-window'); e.value = 1000; "  # past the range:
                            "e.dispatchEvent(new Event('input')); e.dispatchEvent(new Event('change'))")  # held at 255
        moved = browser.wait_for(page, f"const c = window.clwave.current(); return c.fig.seq > {first['seq']} && "
                                       "c.fig.final && !window.clwave.state.moving && c.fig")
        assert moved["tf_window"] == pytest.approx([255 - 29.9, 255 + 29.9])
        camera = clwave.Camera(moved["azimuth"], moved["elevation"], SIZE, extent=moved["extent"])
        expect = clwave.raytrace(wv, camera, tolerance=1e-2, transfer_function=clwave.TransferFunction.preset(
            "grey", window=tuple(moved["tf_window"]))).to_uint8(background=(0.0, 0.0, 0.0))
        got = iio.imread(io.BytesIO(browser.current_frame(page)[1]))
        assert expect.std() > 1 and np.abs(got.astype(int) - expect).max() <= 1
        page.save_screenshot(str(tmp_path / "moved.png"))
        print(tmp_path)
