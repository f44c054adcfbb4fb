"""clwave in a notebook (trial27): an RGBA photo given as classified is warned of, nested thresholded labels are a
label map, results, frames and turntables show as pictures with a short text, an "auto" window is resolved once a
model, and every viewer closes at once."""

import base64
import io
import re
import sys
import threading
import urllib.error
import urllib.request
import warnings

import numpy as np
import pytest
from PIL import Image, ImageSequence

import clwave
from clwave.errors import ClwaveWarning
from clwave.io.result import RenderResult
from clwave.model.labels import JUMPS, looks_like_labels


def _trial_rgba(m=32):
    """trial27's recipe (make_data.py, 96^3 there): a shell of straight (220, 60, 40, alpha 80) around a cube of
    (40, 120, 230, alpha 200), alpha 0 elsewhere, uint8."""
    zz, yy, xx = np.mgrid[0:m, 0:m, 0:m] / (m - 1) * 2 - 1
    r = np.sqrt(zz ** 2 + yy ** 2 + xx ** 2)
    rgba = np.zeros((m, m, m, 4), np.uint8)
    rgba[(r > 0.6) & (r < 0.75)] = (220, 60, 40, 80)
    rgba[(np.abs(zz) < 0.3) & (np.abs(yy) < 0.3) & (np.abs(xx) < 0.3)] = (40, 120, 230, 200)
    return rgba


def _model(volume, **options):
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        clwave.WaveletVolume.from_volume(volume, levels=1, **options)
    return [str(w.message) for w in seen if issubclass(w.category, ClwaveWarning)]


def test_a_photos_straight_rgba_given_as_classified_is_warned_of_naming_photo():
    seen = _model(clwave.Volume(_trial_rgba()))
    assert len(seen) == 1 and "exceeds its alpha in 100%" in seen[0] and "photo=True" in seen[0] and \
        "preset('photo')" in seen[0]


def test_premultiplied_rgba_a_photo_and_a_classification_are_not_warned_of():
    rgba = _trial_rgba().astype(np.float64)
    premultiplied = np.concatenate([np.rint(rgba[..., :3] * rgba[..., 3:] / 255), rgba[..., 3:]], -1).astype(np.uint8)
    assert np.all(premultiplied[..., :3].max(-1) <= premultiplied[..., 3])  # the oracle: colour never above alpha
    classified = clwave.TransferFunction.preset("hydrogen").classify(clwave.phantom("hydrogen", 24))
    for volume in (clwave.Volume(premultiplied), clwave.Volume(_trial_rgba(), photo=True), classified):
        assert _model(volume) == []


def test_the_command_line_names_its_photo_option(tmp_path, capsys):
    from clwave.cli import main

    np.save(tmp_path / "rgba.npy", _trial_rgba(24))
    code = main(["compress", str(tmp_path / "rgba.npy"), "--levels", "1", "-o", str(tmp_path / "m.clw")])
    err = capsys.readouterr().err
    assert code == 0 and err.count("exceeds its alpha") == 1 and "--tf photo" in err and "photo=True" not in err


def _nested_labels(n=48):
    """trial27's seg128_u16 recipe at n^3: a smooth field (Gaussian halos) thresholded at 0.1, 0.3, 0.6, 1.0 and 1.5,
    labels 0 .. 5 nested, uint16."""
    rng = np.random.default_rng(27)
    z, y, x = np.ogrid[-1:1:n * 1j, -1:1:n * 1j, -1:1:n * 1j]
    field = np.zeros((n, n, n))
    for c, s, a in zip(rng.uniform(-0.6, 0.6, (6, 3)), rng.uniform(0.1, 0.3, 6), rng.uniform(1, 2, 6)):
        field += a * np.exp(-((z - c[0]) ** 2 + (y - c[1]) ** 2 + (x - c[2]) ** 2) / (2 * s * s))
    seg = np.zeros(field.shape, np.uint16)
    for label, threshold in enumerate([0.1, 0.3, 0.6, 1.0, 1.5], 1):
        seg[field > threshold] = label
    return seg


def test_nested_thresholded_labels_are_a_label_map_though_every_boundary_steps_by_one():
    seg = _nested_labels()
    step = np.abs(np.diff(seg.astype(np.int32), axis=2))
    assert len(np.unique(seg)) == 6 and np.count_nonzero(step > 1) < JUMPS * np.count_nonzero(step)  # no jumps
    assert looks_like_labels(seg) and clwave.Volume(seg).labels
    assert any("looks like a label map" in w for w in _model(clwave.Volume(seg)))
    nine = np.rint(clwave.phantom("hydrogen", 48).data * 8).astype(np.uint8)  # 0 .. 8, smooth: the jumps still rule
    assert len(np.unique(nine)) == 9 and not looks_like_labels(nine)


@pytest.fixture(scope="module")
def small():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ClwaveWarning)
        return clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", 20), levels=1).threshold(keep=0.3)


def _range_text(values):
    return f"{float(values.min()):.3g} .. {float(values.max()):.3g}"


def test_a_result_and_a_frame_show_a_short_text_and_the_picture(small):
    result = clwave.splat(small, clwave.Camera(size=24))
    text = repr(result)
    assert text == (f"RenderResult(splat X-ray, 24x24x1 float32, values {_range_text(result.image)}, "
                    f"{result.meta['seconds']['total']:.3g} s)")
    frames = list(clwave.progressive(small, clwave.Camera(size=24), steps=2))
    for frame in frames:
        text = repr(frame)
        assert text.startswith(f"ProgressiveFrame({frame.index}: splat X-ray, 24x24x1 float32, values "
                               f"{_range_text(frame.image)}, coefficients {frame.coefficients}, ") and len(text) < 300
        with Image.open(io.BytesIO(frame._repr_png_())) as im:
            np.testing.assert_array_equal(np.asarray(im), RenderResult(frame.image, frame.meta).picture())
    shaded = RenderResult(np.full((3, 4, 4), 0.5, np.float32), {"mode": "emission-absorption"})
    assert repr(shaded) == "RenderResult(shaded RGBA, 3x4x4 float32, alpha 0.5 .. 0.5)"


def test_a_turntable_shows_as_its_gif_without_rendering_again(small, monkeypatch):
    turn = clwave.turntable(small, 3, clwave.Camera(size=20))
    renderer = sys.modules["clwave.splat.renderer"]
    monkeypatch.setattr(renderer, "splat", lambda *a, **k: pytest.fail("rendered again"))
    shown = re.fullmatch(r'<img src="data:image/gif;base64,([A-Za-z0-9+/=]+)" alt="(Turntable\(.*\))"/>',
                         turn._repr_html_())
    assert shown and shown.group(2).startswith("Turntable(splat X-ray, 3x20x20x1 float32, values ")
    with Image.open(io.BytesIO(base64.b64decode(shown.group(1)))) as gif:
        frames = [np.asarray(f.convert("L")) for f in ImageSequence.Iterator(gif)]
        assert gif.info["duration"] == 100 and gif.info["loop"] == 0
    assert len(frames) == 3
    for frame, picture in zip(frames, turn.pictures()):  # grey levels: the GIF's palette holds them exactly
        np.testing.assert_array_equal(frame, picture)


def test_an_auto_window_is_resolved_once_a_model_whatever_the_function(small, monkeypatch):
    classified = sys.modules["clwave.raytrace.classified"]
    calls = []
    monkeypatch.setattr(classified, "auto_window", lambda v: calls.append(len(v)) or (0.0, 0.5))
    cam = clwave.Camera(size=12)
    functions = [clwave.TransferFunction.preset("hydrogen", window="auto"),
                 clwave.TransferFunction.preset("grey", window="auto")]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ClwaveWarning)
        results = [clwave.raytrace(small, cam, transfer_function=tf) for tf in functions * 2]
    assert len(calls) == 1
    assert all(r.meta["tf_window"] == [0.0, 0.5] for r in results)


def test_an_auto_window_at_render_time_stays_within_the_inputs_range(small):
    """The field rings below the input's least value (0, empty space): its 0.5 percentile is taken up to the least
    value, which the function's first point then classifies (transparent), not a faint fog everywhere."""
    data = clwave.phantom("hydrogen", 20).data
    tracer = clwave.RayTracer(small)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ClwaveWarning)
        meta = tracer.render(clwave.Camera(size=12), transfer_function=clwave.TransferFunction.preset("grey")).meta
    lo, hi = np.percentile(tracer.scalar.sample.astype(np.float64), (0.5, 99.5))
    assert lo < data.min() < hi <= data.max()  # the case: rings below, not above
    assert meta["tf_window"] == pytest.approx([float(data.min()), hi], rel=1e-12, abs=1e-12)


def _refused(url):
    """Whether nothing listens at ``url`` any more; a viewer that does answers its page (a whole request: a
    connection opened and dropped unanswered would be the server's to clean up, after the test)."""
    try:
        urllib.request.urlopen(url, timeout=30).read()
    except urllib.error.URLError as exc:
        if isinstance(exc.reason, ConnectionRefusedError):
            return True
        raise
    return False


def test_close_all_closes_every_viewer_frees_its_port_and_ends_its_thread(small):
    from clwave.view import main_end

    main_end.close_all()  # none left by another test
    viewers = [clwave.view(small, size=16) for _ in range(2)]
    closed_first = clwave.view(small, size=16)
    closed_first.close()
    assert not any(_refused(v.url) for v in viewers) and _refused(closed_first.url)
    assert clwave.Viewer.close_all() == 2
    assert all(_refused(v.url) for v in viewers)
    assert not any(v._background.thread.is_alive() for v in viewers)
    assert not [t for t in threading.enumerate() if t.name == "clwave-view-server"]
    assert clwave.Viewer.close_all() == 0
