"""Transfer functions: interpolation, classification (q = rgb·alpha), presets, windows, I/O, errors."""

import json

import numpy as np
import pytest

from clwave.errors import InputError
from clwave.io.phantoms import analytic
from clwave.model.tf_passes import auto_window
from clwave.model.transfer import TransferFunction
from clwave.model.volume import Volume

THREE = [(0.0, 0.0, 0.0, 1.0, 0.0),
         (10.0, 1.0, 0.0, 0.0, 1.0),
         (20.0, 1.0, 1.0, 1.0, 0.5)]


def test_interpolation_at_between_and_outside_points():
    tf = TransferFunction(THREE)
    rgb, alpha = tf([0.0, 10.0, 20.0])
    np.testing.assert_array_equal(rgb, [[0, 0, 1], [1, 0, 0], [1, 1, 1]])
    np.testing.assert_array_equal(alpha, [0.0, 1.0, 0.5])
    rgb, alpha = tf([5.0, 15.0, 2.5])
    np.testing.assert_allclose(rgb, [[0.5, 0, 0.5], [1, 0.5, 0.5], [0.25, 0, 0.75]], atol=1e-15)
    np.testing.assert_allclose(alpha, [0.5, 0.75, 0.25], atol=1e-15)
    # constant outside: the end rows, exactly
    rgb, alpha = tf([-1e9, -0.001, 20.001, 1e9])
    np.testing.assert_array_equal(rgb, [[0, 0, 1], [0, 0, 1], [1, 1, 1], [1, 1, 1]])
    np.testing.assert_array_equal(alpha, [0.0, 0.0, 0.5, 0.5])


def test_call_keeps_shape():
    rgb, alpha = TransferFunction(THREE)(np.full((2, 3, 4), 7.0))
    assert rgb.shape == (2, 3, 4, 3) and alpha.shape == (2, 3, 4)
    assert rgb.dtype == alpha.dtype == np.float64


@pytest.mark.parametrize("k", [2, 5, 8, 9, 40])
def test_matches_linear_interpolation_for_any_number_of_points(k, rng):
    xs = np.cumsum(rng.uniform(0.1, 2.0, k))
    pts = np.column_stack([xs, rng.random((k, 3)), rng.uniform(0, 3, k)])
    tf = TransferFunction(pts)
    v = rng.uniform(xs[0] - 1, xs[-1] + 1, 5000)
    v[:k] = xs                                   # every control point exactly
    rgb, alpha = tf(v)
    for c in range(3):
        np.testing.assert_allclose(rgb[:, c], np.interp(v, xs, pts[:, 1 + c]), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(alpha, np.interp(v, xs, pts[:, 4]), rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(alpha[:k], pts[:, 4])


def test_window_maps_normalised_points():
    tf = TransferFunction([(0, 0, 0, 0, 0), (1, 1, 1, 1, 2)], window=(100, 300))
    rgb, alpha = tf([100.0, 150.0, 300.0, 50.0, 400.0])
    np.testing.assert_allclose(alpha, [0, 0.5, 2, 0, 2], atol=1e-15)
    np.testing.assert_allclose(rgb[:, 1], [0, 0.25, 1, 0, 1], atol=1e-15)
    np.testing.assert_allclose(tf.data_points(), [100, 300])
    # a per-call window overrides the function's own
    _, alpha = tf([150.0], window=(0, 150))
    assert alpha[0] == 2.0


def test_classify_gives_q_equal_rgb_times_alpha(rng):
    tf = TransferFunction([(0.0, 0.2, 0.4, 0.9, 0.0), (0.3, 1.0, 0.5, 0.1, 0.25),
                           (0.7, 0.3, 0.9, 0.6, 0.05), (1.0, 1.0, 1.0, 1.0, 0.4)])
    vol = Volume(rng.uniform(-0.2, 1.2, (6, 7, 9)), spacing=(2.0, 0.5, 1.0), origin=(1, 2, 3))
    out = tf.classify(vol)
    assert out.shape == vol.shape and out.channels == 4 and out.data.dtype == np.float32
    assert out.spacing == vol.spacing and out.origin == vol.origin
    rgb, alpha = tf(vol.data)
    alpha = alpha / 0.5  # the opacity per voxel, the smallest spacing 0.5: per world unit (docs/model.md §5)
    np.testing.assert_array_equal(out.data[..., 3], alpha.astype(np.float32))
    np.testing.assert_array_equal(out.data[..., :3], (rgb * alpha[..., None]).astype(np.float32))
    # and against a plain np.interp reference
    for c in range(3):
        ref = np.interp(vol.data, tf.points[:, 0], tf.points[:, 1 + c]) * \
            np.interp(vol.data, tf.points[:, 0], tf.points[:, 4]) / 0.5
        np.testing.assert_allclose(out.data[..., c], ref, rtol=1e-6, atol=1e-9)


def test_classify_large_volume_uses_threads_and_agrees(rng):
    """More than a million voxels take the chunked, threaded path; spot-check it."""
    tf = TransferFunction.preset("hydrogen")
    data = rng.random((40, 160, 170)).astype(np.float32)       # 1.09 M voxels
    out = tf.classify(Volume(data))
    rgb, alpha = tf(data)
    np.testing.assert_array_equal(out.data[..., 3], alpha.astype(np.float32))
    np.testing.assert_array_equal(out.data[..., 0], (rgb[..., 0] * alpha).astype(np.float32))


@pytest.mark.parametrize("name", TransferFunction.PRESETS)
def test_presets_construct_and_classify(name):
    tf = TransferFunction.preset(name)
    assert tf.name == name and len(tf.points) >= 2
    values = np.linspace(-1500.0, 3500.0, 4 * 5 * 6).reshape(4, 5, 6)
    if name == "hydrogen":
        values = np.linspace(0.0, 1.0, 120).reshape(4, 5, 6)
    out = tf.classify(Volume(values))
    d = out.data
    assert d.shape == (4, 5, 6, 4)
    assert np.all(np.isfinite(d)) and d.min() >= 0
    assert d[..., 3].max() > 0                                   # something is visible
    assert np.all(d[..., :3] <= d[..., 3:] * (1 + 1e-6))         # colour <= 1: q <= alpha
    json.dumps(tf.to_dict())


def test_preset_windows_and_opacity_scales():
    bone = TransferFunction.preset("ct-bone")
    assert bone.window == (-1000.0, 2000.0)
    _, a = bone([-1000.0, 0.0, 150.0, 1000.0, 3000.0])           # Hounsfield units
    assert a[0] == a[1] == a[2] == 0.0 and a[3] == pytest.approx(0.5) and a[4] == pytest.approx(0.5)
    soft = TransferFunction.preset("ct-soft-tissue")
    _, a = soft([-800.0, 40.0, 300.0])
    assert a[0] == 0.0 and 0 < a[1] < a[2]
    assert TransferFunction.preset("mri").window == "auto"
    assert TransferFunction.preset("grey").window == "auto"
    assert TransferFunction.preset("hydrogen").window == (0.0, 1.0)
    assert TransferFunction.preset("Gray").name == "grey"
    # a preset's own window can be replaced
    assert TransferFunction.preset("ct-bone", window=(0, 1)).window == (0.0, 1.0)


def test_hydrogen_preset_optical_depth_through_a_lobe():
    """Design target: A = ∫alpha ≈ 2..4 on a ray through one lobe, n = 128..256."""
    tf = TransferFunction.preset("hydrogen")
    for n, lo, hi in ((128, 1.5, 3.0), (256, 3.0, 5.0)):
        f = analytic("hydrogen", n)
        t = np.linspace(-n / 2, n / 2, 40001)
        ray = np.stack([t, 0 * t, 0 * t + 6 * n / 36], axis=1)   # along x, through a lobe's peak
        _, alpha = tf(f(ray))
        depth = float(alpha.sum() * (t[1] - t[0]))
        assert lo < depth < hi, (n, depth)
    # low density is transparent
    _, alpha = tf([0.0, 0.01, 0.05])
    np.testing.assert_array_equal(alpha, 0.0)


def test_auto_window_uses_percentiles(rng):
    data = rng.normal(50.0, 10.0, (20, 30, 40))
    tf = TransferFunction([(0, 0, 0, 0, 0), (1, 1, 1, 1, 1)], window="auto")
    lo, hi = np.percentile(data, [0.5, 99.5])
    assert tf.resolve_window(data) == pytest.approx((lo, hi), rel=1e-12)
    out = tf.classify(Volume(data))
    expected = np.clip((data - lo) / (hi - lo), 0, 1)
    np.testing.assert_allclose(out.data[..., 3], expected, atol=2e-6)
    # a fixed window overrides "auto" in classify
    out = tf.classify(Volume(data), window=(0, 100))
    np.testing.assert_allclose(out.data[..., 3], np.clip(data / 100, 0, 1), atol=2e-6)


def test_auto_window_subsamples_large_volumes_and_handles_constants(rng):
    data = rng.uniform(0, 1000, 3_000_000)
    lo, hi = auto_window(data)
    assert lo == pytest.approx(5, abs=2) and hi == pytest.approx(995, abs=2)
    data[::7] = np.nan
    assert auto_window(data) == pytest.approx((lo, hi), abs=3)        # NaN ignored
    assert auto_window(np.full(10, 3.0)) == (2.5, 3.5)
    assert auto_window(np.r_[np.zeros(1000), 1.0]) == (0.0, 1.0)        # percentiles equal -> min/max
    with pytest.raises(InputError, match="no finite"):
        auto_window([np.nan, np.inf])


@pytest.mark.parametrize("tf", [
    TransferFunction.preset("ct-bone"),
    TransferFunction.preset("mri"),
    TransferFunction([(0.1 + 0.2, 1 / 3, 0.0, 1.0, 1e-300), (7 / 3, 0.7, 0.1, 0.2, 0.12345678901234568)],
                     window=(-1 / 7, 1e6 / 3), name="custom"),
    TransferFunction(THREE),
], ids=["ct-bone", "mri", "awkward-floats", "no-window"])
def test_to_dict_round_trips_exactly_through_json(tf):
    d = json.loads(json.dumps(tf.to_dict()))
    back = TransferFunction.from_dict(d)
    assert back == tf
    np.testing.assert_array_equal(back.points, tf.points)
    assert back.window == tf.window and back.name == tf.name
    assert TransferFunction.from_dict({"points": THREE}) == TransferFunction(THREE)


def test_rgb_volume_classification():
    tf = TransferFunction([(0, 0, 0, 0, 0.0), (1, 0, 0, 0, 0.8)])       # opacity = 0.8 · luminance
    rgb8 = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 255],
                     [0, 0, 0], [100, 150, 200], [10, 20, 30], [128, 128, 0]], dtype=np.uint8)
    vol = Volume(rgb8.reshape(2, 2, 2, 3))
    out = tf.classify(vol).data.reshape(-1, 4)
    colour = rgb8 / 255.0
    lum = colour @ [0.299, 0.587, 0.114]
    np.testing.assert_allclose(out[:, 3], 0.8 * lum, rtol=1e-6)
    np.testing.assert_allclose(out[:, :3], colour * (0.8 * lum)[:, None], rtol=1e-6, atol=1e-9)
    # the same colours given in [0, 1] classify the same
    out01 = tf.classify(Volume(colour.reshape(2, 2, 2, 3))).data.reshape(-1, 4)
    np.testing.assert_allclose(out01, out, rtol=1e-6, atol=1e-9)
    # RGBA: opacity times A
    a8 = np.array([255, 0, 128, 64, 255, 255, 0, 10], dtype=np.uint8)
    rgba = np.concatenate([rgb8, a8[:, None]], axis=1).reshape(2, 2, 2, 4)
    outa = tf.classify(Volume(rgba)).data.reshape(-1, 4)
    np.testing.assert_allclose(outa[:, 3], 0.8 * lum * a8 / 255, rtol=1e-6)
    np.testing.assert_allclose(outa[:, :3], colour * (0.8 * lum * a8 / 255)[:, None], rtol=1e-6,
                               atol=1e-9)


def test_classifying_a_volume_all_transparent_is_refused():
    """A transfer function that gives no voxel any opacity (HU ct-bone on attenuation per mm, on an all-zero volume,
    a colour volume darker than its opacity ramp starts) raises NothingVisibleError, an InputError, in the API's
    words and in the command line's (cli); opacity at one voxel is enough to classify."""
    from clwave.errors import NothingVisibleError

    mu = np.zeros((4, 4, 4), np.float32)
    mu[1:3, 1:3, 1:3] = 0.0386  # 1000 HU as attenuation per mm
    bone = TransferFunction.preset("ct-bone")
    with pytest.raises(NothingVisibleError) as exc:
        bone.classify(Volume(mu))
    assert isinstance(exc.value, InputError)
    line = ("the transfer function ct-bone gives no voxel of this volume any opacity: its points span -1000 .. 2000 "
            "and the volume's values lie within 0 .. 0.0386; give a window in the input's units")
    assert str(exc.value) == f"{line} (window=(lo, hi)) or another function"
    assert exc.value.cli_message() == f"{line} (--tf-window LO,HI) or another preset"
    rgba = bone.classify(Volume(mu), window=(-0.02, 0.04))  # the window in the input's units: 0.0386 is bone
    assert rgba.data[..., 3].max() > 0.4 and rgba.data[0, 0, 0, 3] == 0
    with pytest.raises(NothingVisibleError, match="values lie within 0 .. 0;"):
        bone.classify(Volume(np.zeros((4, 4, 4))))
    ramp = TransferFunction([(0.0, 1, 1, 1, 0.0), (0.5, 1, 1, 1, 0.0), (1.0, 1, 1, 1, 1.0)])  # no name
    dark = np.full((4, 4, 4, 3), 60, np.uint8)
    with pytest.raises(NothingVisibleError, match=r"^the transfer function gives .* points span 0 .. 1 and the "
                                                  r"volume's luminance \(0 .. 1\) lie within 0.2353 .. 0.2353"):
        ramp.classify(Volume(dark))
    one = np.zeros((4, 4, 4), np.float32)
    one[2, 2, 2] = 2000.0
    assert np.count_nonzero(bone.classify(Volume(one)).data[..., 3]) == 1


def test_docstrings_state_pre_classification():
    for doc in (TransferFunction.__doc__, TransferFunction.classify.__doc__):
        assert "new wavelet transform" in " ".join(doc.split())
    assert "RGBA" in TransferFunction.classify.__doc__


@pytest.mark.parametrize("args, match", [
    (([(0, 0, 0, 0, 0)],), "at least 2 points"),
    (([],), "points must be rows"),
    (([(0, 0, 0, 0)] * 2,), "points must be rows"),
    (("abc",), "points must be rows"),
    (([(0, 0, 0, 0, 0), (0, 1, 1, 1, 1)],), "strictly increasing"),
    (([(1, 0, 0, 0, 0), (0, 1, 1, 1, 1)],), "strictly increasing"),
    (([(0, 0, 0, 0, 0), (np.nan, 1, 1, 1, 1)],), "not finite"),
    (([(0, 0, 0, 0, 0), (1, 1, 1, 1, np.inf)],), "not finite"),
    (([(0, 0, 0, 0, -0.1), (1, 1, 1, 1, 1)],), "negative"),
    (([(0, 0, 0, 0, 0), (1, 1.5, 1, 1, 1)],), r"outside \[0, 1\]"),
    (([(0, 0, -0.2, 0, 0), (1, 1, 1, 1, 1)],), r"outside \[0, 1\]"),
    (([(0, 0, 0, 0, 0), (1, 1, 1, 1, 1)], (1, 1)), "lo < hi"),
    (([(0, 0, 0, 0, 0), (1, 1, 1, 1, 1)], (2, 1)), "lo < hi"),
    (([(0, 0, 0, 0, 0), (1, 1, 1, 1, 1)], (0, np.inf)), "finite"),
    (([(0, 0, 0, 0, 0), (1, 1, 1, 1, 1)], (0, np.nan)), "finite"),
    (([(0, 0, 0, 0, 0), (1, 1, 1, 1, 1)], "percentile"), "'auto' or \\(lo, hi\\)"),
    (([(0, 0, 0, 0, 0), (1, 1, 1, 1, 1)], (1, 2, 3)), "'auto' or \\(lo, hi\\)"),
    (([(0, 0, 0, 0, 0), (1, 1, 1, 1, 1)], None, 5), "name"),
])
def test_bad_transfer_functions_raise_one_line_errors(args, match):
    with pytest.raises(InputError, match=match) as err:
        TransferFunction(*args)
    assert "\n" not in str(err.value)


def test_bad_preset_window_and_volume_errors():
    with pytest.raises(InputError, match="ct-bone, ct-soft-tissue, mri, hydrogen, grey") as err:
        TransferFunction.preset("rainbow")
    assert "\n" not in str(err.value)
    with pytest.raises(InputError, match="lo < hi"):
        TransferFunction.preset("ct-bone", window=(5, 5))
    tf = TransferFunction(THREE)
    with pytest.raises(InputError, match="lo < hi"):
        tf.classify(Volume(np.zeros((2, 2, 2))), window=(3, -3))
    with pytest.raises(InputError) as err:  # not finite: the same words
        TransferFunction(THREE, window=(0, float("inf")))
    assert str(err.value) == "window (0, inf) must be two finite numbers (lo, hi) with lo < hi"
    with pytest.raises(InputError, match="Volume"):
        tf.classify(np.zeros((2, 2, 2)))
    with pytest.raises(InputError, match="2-channel"):
        tf.classify(Volume(np.zeros((2, 2, 2, 2))))
    with pytest.raises(InputError, match="2-channel"):
        tf.resolved(Volume(np.zeros((2, 2, 2, 2))))
    with pytest.raises(InputError, match="negative"):
        tf.classify(Volume(-np.ones((2, 2, 2, 3))))
    with pytest.raises(InputError, match="65535"):
        tf.classify(Volume(np.full((2, 2, 2, 3), 1e6)))
    with pytest.raises(InputError, match="points"):
        TransferFunction.from_dict({"window": None})
    with pytest.raises(InputError, match="format"):
        TransferFunction.from_dict({"points": THREE, "format": "other"})


def test_resolved_records_the_window_classify_used(rng):
    data = rng.normal(0.0, 1.0, (10, 11, 12)).astype(np.float32)
    tf = TransferFunction.preset("grey")
    fixed = tf.resolved(Volume(data))
    assert fixed.window == pytest.approx(tuple(np.percentile(data, [0.5, 99.5])), rel=1e-12)
    np.testing.assert_array_equal(fixed.classify(Volume(data)).data, tf.classify(Volume(data)).data)
    rgb = Volume(rng.integers(0, 256, (4, 5, 6, 3)).astype(np.float32))
    np.testing.assert_array_equal(tf.resolved(rgb).classify(rgb).data, tf.classify(rgb).data)
    assert TransferFunction.preset("ct-bone").resolved(Volume(data)).window == (-1000.0, 2000.0)


def test_check_visible_refuses_exactly_what_classify_refuses():
    """``check_visible`` (min, max and the points between; no classification) against ``classify`` itself, over
    random scalar volumes and windows of a preset, those that miss the values included."""
    from clwave.errors import NothingVisibleError

    rng = np.random.default_rng(5)
    tf = TransferFunction.preset("ct-bone")
    outcomes = []
    for _ in range(60):
        lo = rng.uniform(-3000, 3000)
        vol = Volume(rng.uniform(lo, lo + rng.uniform(1, 800), (6, 6, 6)).astype(np.float32))
        refused = []
        for check in (tf.check_visible, tf.classify):
            try:
                check(vol)
                refused.append(False)
            except NothingVisibleError:
                refused.append(True)
        assert refused[0] == refused[1]
        outcomes.append(refused[0])
    assert 5 < sum(outcomes) < 55  # both kinds met


def test_a_colour_volumes_window_in_sample_units_is_warned():
    """A colour volume is classified on its luminance, 0 .. 1 whatever its sample type: a window in 8-bit units
    (0 .. 100 on an RGB stack) left a new user's image at 0.2 % of its range, silently; it is told in one line, and a
    window within 0 .. 1 (or "auto") is not."""
    import warnings

    from clwave.errors import ClwaveWarning

    rgb = Volume(np.random.default_rng(0).integers(0, 255, (8, 8, 8, 3)).astype(np.uint8))
    with pytest.warns(ClwaveWarning, match=r"window of 0 .. 100 puts all of it in 1.0% of the window; give one "
                                           r"within 0 .. 1 \(window=\(lo, hi\)\)"):
        TransferFunction.preset("grey", window=(0, 100)).classify(rgb)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for window in ((0, 0.4), "auto", (-0.5, 1.2)):
            TransferFunction.preset("grey", window=window).classify(rgb)


def _ellipsoid_volume(inside, outside, n=24):
    """An ellipsoid of value ``inside`` in ``outside`` (1 mm voxels): an MRI's body in its noise, or a CT's in air."""
    z, y, x = np.mgrid[:n, :n, :n] - (n - 1) / 2
    body = (x / 10) ** 2 + (y / 8) ** 2 + (z / 11) ** 2 <= 1
    return Volume(np.where(body, inside, outside).astype(np.float32))


@pytest.mark.parametrize("name, window, inside, outside, warned", [
    ("ct-bone", None, 600.0, 20.0, True),          # trial28's M4: a T1 MRI (fat 600, noise 20) under a CT preset
    ("ct-soft-tissue", None, 600.0, 20.0, True),
    ("ct-bone", (0.0, 800.0), 600.0, 20.0, False),  # a window moved off air: the user's, in its units
    ("mri", None, 600.0, 20.0, False),
    ("ct-bone", None, 1000.0, -1000.0, False),      # a CT in HU: air about it
    ("ct-bone", None, 1000.0, -600.0, False),       # lung, no air: a CT cropped inside the chest
    ("ct-bone", None, 1000.0, -400.0, True),        # nothing at or below -500
])
def test_a_ct_preset_on_values_that_are_no_hu_is_warned(name, window, inside, outside, warned):
    """A CT preset whose window reaches air (-1000 HU) on a scalar volume with no value at or below -500 (no air, no
    lung: an MRI's or a PET's values) warns in one line naming the mri and grey presets and a window; a window the
    user moved, another preset, or a CT does not."""
    import warnings

    from clwave.errors import ClwaveWarning

    vol = _ellipsoid_volume(inside, outside)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        TransferFunction.preset(name, window=window).classify(vol)
    lines = [str(w.message) for w in seen if "Hounsfield" in str(w.message)]
    assert len(lines) == warned and all(isinstance(w.message, ClwaveWarning) for w in seen)
    if warned:
        assert lines[0].startswith(f"the transfer function {name} is for CT in Hounsfield units, and this volume's "
                                   f"least value is {outside:g}, with no air")
        assert "preset('mri') or 'grey', or window= in its units" in lines[0] and "\n" not in lines[0]


def test_a_ct_preset_on_an_mri_warns_on_the_command_line(tmp_path, capsys):
    """The command line's words: --tf mri, --tf grey, --tf-window (trial28's `render SE7 --tf ct-bone`)."""
    from test_cli import run

    np.save(tmp_path / "mri.npy", _ellipsoid_volume(600.0, 20.0).data)
    code, out, err = run(capsys, "compress", str(tmp_path / "mri.npy"), "--tf", "ct-bone", "-o",
                         str(tmp_path / "m.clw"))
    assert code == 0
    assert "clwave: warning: the transfer function ct-bone is for CT in Hounsfield units, and this volume's least " \
           "value is 20, with no air (-1000) or lung (below -500): it may be no CT (an MRI: --tf mri or --tf grey, " \
           "or --tf-window LO,HI in its units)" in err
