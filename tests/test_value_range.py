"""Post-classification sees the input's range: the transfer function applied to the field clamped to the volume's
[min, max] (docs/raytracing.md §10), the range a model keeps from its volume and its .clw file."""

import json
import re
import warnings
import zlib

import h5py
import numpy as np
import pytest

import clwave
from clwave.raytrace.classified import clamped
from clwave.raytrace.reference import classified_reference


def shell(n=32):
    """A foam-like 8-bit volume: a sharp wall 0 | 255, whose 5 % model rings far past 255 and below 0."""
    z, y, x = np.mgrid[:n, :n, :n] - (n - 1) / 2
    wall = np.abs(np.sqrt(x ** 2 + y ** 2 + z ** 2) - n * 10 / 32) < 2.5 * n / 32
    return clwave.Volume(np.where(wall, 255, 0).astype(np.uint8))


@pytest.fixture(scope="module")
def ringing():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the budget drops part of the approximation band: the point here
        wv = clwave.WaveletVolume.from_volume(shell(), levels=2).threshold(keep=0.05)
    field = wv.reconstruct().data
    assert wv.value_range == (0.0, 255.0) and field.max() > 300 and field.min() < -50
    return wv


def unclamped(wv):
    """``wv`` as a model that does not know its input's range (a .clw written before it)."""
    out = wv.threshold(keep=1.0)
    out.value_range = None
    return out


def test_a_window_above_the_inputs_maximum_draws_nothing(ringing):
    """The foam case: grey over 256.7 .. 316.5, above every value of the input but not of its model, shaded: the
    background exactly, and said so; without the range (as before) the ringing draws specks."""
    tf = clwave.TransferFunction.preset("grey", window=(256.7, 316.5))
    cam = clwave.Camera(30, 20, size=32)
    res = clwave.RayTracer(ringing).render(cam, transfer_function=tf)
    assert not np.any(res.image) and "the input's values lie within 0 .. 255" in res.meta["nothing_visible"]
    specks = clwave.RayTracer(unclamped(ringing)).render(cam, transfer_function=tf).image
    assert np.count_nonzero(specks[..., 3] > 1e-3) > 20


def test_a_window_inside_the_range_draws_what_it_did(ringing):
    """Points within [min, max]: the same transfer function, so the same image bit for bit (shaded and not)."""
    tf = clwave.TransferFunction.preset("grey", window=(60.0, 200.0))
    assert clamped(tf, (0.0, 255.0)) is tf
    cam = clwave.Camera(30, 20, size=24)
    for shading in (True, False):
        a = clwave.RayTracer(ringing).render(cam, transfer_function=tf, shading=shading).image
        b = clwave.RayTracer(unclamped(ringing)).render(cam, transfer_function=tf, shading=shading).image
        assert a[..., 3].max() > 0.1 and np.array_equal(a, b)


@pytest.mark.parametrize("seed", range(4))
def test_the_rewritten_function_is_the_function_of_the_clamped_value(seed):
    """clamped(tf, range) at any value equals tf at the value clipped to the range (float64, np.interp and np.clip),
    for points across, beside and beyond the range, and a range of one value."""
    rng = np.random.default_rng(seed)
    values = np.sort(rng.uniform(-100, 400, rng.integers(2, 7)))
    tf = clwave.TransferFunction(np.column_stack([values, rng.uniform(0, 1, (len(values), 3)),
                                                  rng.uniform(0, 2, len(values))]))
    s = np.concatenate([rng.uniform(-300, 600, 2000), values, [0.0, 255.0, 100.0]])
    for lo, hi in ((0.0, 255.0), (-500.0, -200.0), (450.0, 900.0), (100.0, 100.0), (values[1], values[-1] + 1)):
        rgb, alpha = clamped(tf, (lo, hi))(s)
        clip = np.clip(s, lo, hi)
        expect = [np.interp(clip, values, tf.points[:, c]) for c in range(1, 5)]
        assert np.allclose(rgb, np.stack(expect[:3], axis=-1), rtol=0, atol=1e-12)
        assert np.allclose(alpha, expect[3], rtol=0, atol=1e-12)


@pytest.mark.parametrize("seed", range(2))
def test_the_clamped_classification_against_the_float64_oracle(ringing, seed):
    """A random transfer function whose points reach past the input's range, shaded: each value within the
    tolerance of the brute-force float64 oracle (np.clip of the field, cut where it meets the range's ends), and
    the clamp matters (the oracle without it is farther off)."""
    rng = np.random.default_rng(seed)
    values = np.concatenate([[-60.0, -1.0], np.sort(rng.uniform(1, 254, 3)), [256.0, 320.0]])
    opacity = np.concatenate([[2.0, 0.0], rng.uniform(0, 0.05, 3), [0.0, 2.0]])  # opaque where only ringing is
    tf = clwave.TransferFunction(np.column_stack([values, rng.uniform(0, 1, (len(values), 3)), opacity]))
    cam = clwave.Camera(30 + 40 * seed, 20, size=6)
    tr = clwave.RayTracer(ringing)
    ref = classified_reference(ringing, cam, tf, tracer=tr)
    loose = clwave.RayTracer(unclamped(ringing))
    assert np.abs(classified_reference(unclamped(ringing), cam, tf, tracer=loose) - ref).max() > 0.05
    for tol in (1e-2, 1e-3):
        img = tr.render(cam, tolerance=tol, transfer_function=tf).image
        assert np.abs(img - ref).max() <= tol, (tol, np.abs(img - ref).max())


def test_the_range_round_trips_through_clw_files(tmp_path):
    """The in-memory and the chunked writer store the input's range (the value subtracted added back); a file
    without it (written before) reads as not known: no clamp."""
    import dask.array as da

    data = (np.random.default_rng(3).uniform(-7, 40, (12, 12, 12))).astype(np.float32)
    vol = clwave.Volume(data, subtracted=-1000.0)
    expect = (float(data.min()) - 1000.0, float(data.max()) - 1000.0)
    memory = clwave.WaveletVolume.from_volume(vol, levels=1)
    chunked = clwave.WaveletVolume.from_volume(clwave.Volume(da.from_array(data, chunks=6), subtracted=-1000.0),
                                               levels=1).threshold(keep=0.5)
    assert memory.value_range == expect == chunked.value_range == chunked.compute().value_range
    for name, model in (("m.clw", memory), ("c.clw", chunked)):
        assert clwave.WaveletVolume.open(model.save(tmp_path / name)).value_range == expect
    assert clwave.WaveletVolume.from_volume(clwave.Volume(np.zeros((8, 8, 8, 4), np.float32)), levels=1) \
        .value_range is None
    with h5py.File(tmp_path / "m.clw", "r+") as h5:  # as written before the range was kept
        header = json.loads(h5.attrs["header"])
        del header["value_range"]
        h5.attrs["header"] = json.dumps(header)
        h5.attrs["header_crc32"] = zlib.crc32(h5.attrs["header"].encode())
    assert clwave.WaveletVolume.open(tmp_path / "m.clw").value_range is None


def test_a_nearly_empty_image_is_told_with_the_window_that_shows_the_model():
    """A blob of peak 10 under grey opaque from 9.5 up (the values its model barely reaches, as the trial's dark
    function on a denoised tomogram): no pixel hides 5 % of the background, and the warning says so, naming the
    values the model holds; the window it names draws the blob (checked on the image: over a tenth of the pixels)."""
    z, y, x = np.mgrid[:32, :32, :32] / 32.0
    vol = clwave.Volume((10 * np.exp(-((x - .5) ** 2 + (y - .5) ** 2 + (z - .5) ** 2) * 20)).astype(np.float32))
    tracer, cam = clwave.RayTracer(clwave.WaveletVolume.from_volume(vol, levels=2)), clwave.Camera(30, 20, size=32)
    with pytest.warns(clwave.ClwaveWarning, match=r"nearly empty: 0 % of its pixels hide 5 % of the background or "
                                                  r"more \(13 of 255 levels.*grey is opaque above 9.5, and "
                                                  r"this model's values lie within") as told:
        faint = tracer.render(cam, transfer_function=clwave.TransferFunction.preset("grey", window=(9.5, 100)))
    assert faint.image[..., 3].max() < 0.05 and not faint.meta["nothing_visible"]
    window = tuple(map(float, re.search(r"window=\(([^,]+), ([^)]+)\)", str(told[0].message)).groups()))
    assert window[0] < 0.01 and 9.99 < window[1] <= 10
    with warnings.catch_warnings():
        warnings.simplefilter("error", clwave.ClwaveWarning)
        shown = tracer.render(cam, transfer_function=clwave.TransferFunction.preset("grey", window=window))
    assert np.mean(shown.image[..., 3] >= 0.05) > 0.1  # measured 0.13: the blob
    centre = np.mean(tracer.wv.content_box(), axis=0)
    with warnings.catch_warnings():  # a clip that leaves little is what was asked for: not told
        warnings.simplefilter("error", clwave.ClwaveWarning)
        little = tracer.render(cam, transfer_function=clwave.TransferFunction.preset("grey", window=window),
                               clip=clwave.Clip(lo=centre - 1, hi=centre + 1)).image
    assert np.mean(little[..., 3] >= 0.05) < 0.01  # nearly empty, as asked
