"""A volume loaded with ``subtract=b`` (``--subtract b``) stores the input's values minus b and records b as the
value ``subtracted`` (the model's, the ``.clw`` file's); transfer functions stay in the input's units (HU for the ct-*
presets) and classify it alike (docs/coordinates.md §1, docs/model.md §5)."""

import json
import zlib

import dask.array as da
import h5py
import numpy as np
import pytest

import clwave
from clwave.errors import FileFormatError, NothingVisibleError
from clwave.model.tf_passes import auto_window
from clwave.model.transfer import TransferFunction
from clwave.model.volume import Volume
from test_cli import run

AIR = -1000.0


def ct_in_hu():
    """Soft tissue (+40 HU) with a bone core (+700 HU) and a pocket of air (-1000 HU), 16^3: the tissue reaches every
    face, so the default framing (the non-zero voxels' box) is the volume's with or without the subtraction."""
    ct = np.full((16, 16, 16), 40.0, np.float32)
    ct[3:13, 3:6, 3:13] = AIR
    ct[6:10, 8:12, 6:10] = 700.0
    return ct


@pytest.fixture
def ct_file(tmp_path):
    np.save(tmp_path / "ct.npy", ct_in_hu())
    return tmp_path / "ct.npy"


def test_load_with_subtract_records_it_and_classifies_in_the_files_units(ct_file):
    hu, shifted = clwave.load(ct_file), clwave.load(ct_file, subtract=AIR)
    assert hu.subtracted == 0.0 and shifted.subtracted == AIR
    np.testing.assert_array_equal(shifted.data, ct_in_hu() - AIR)  # stored: HU + 1000, air at 0
    for tf in (TransferFunction.preset("ct-bone"), TransferFunction.preset("ct-soft-tissue"),
               TransferFunction.preset("ct-bone", window=(-500.0, 1500.0))):
        want, got = tf.classify(hu).data, tf.classify(shifted).data
        np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-7)
        assert tf.classify(shifted).subtracted == 0.0  # classified values are no longer the input's
    bone = TransferFunction.preset("ct-bone").classify(shifted).data[..., 3]
    assert bone[8, 10, 8] == 0.5 and bone[1, 1, 1] == 0.0  # the core is bone, the 40 HU tissue clear (not 1040 HU)


def test_the_old_keywords_are_refused_naming_them(ct_file):
    """No alias for the names used until the eighteenth session (pre-1.0): Python's TypeError names the keyword."""
    with pytest.raises(TypeError, match="'background'"):
        clwave.load(ct_file, background=AIR)
    with pytest.raises(TypeError, match="'offset'"):
        Volume(ct_in_hu(), offset=AIR)
    assert not hasattr(Volume(ct_in_hu()), "offset")


def test_points_without_a_window_and_an_auto_window_are_the_files_too():
    ct = ct_in_hu()
    points = [(-1000.0, 0, 0, 0, 0.0), (0.0, 1, 0, 0, 0.0), (500.0, 1, 1, 1, 0.2)]  # values in HU, window None
    tf = TransferFunction(points)
    np.testing.assert_allclose(tf.classify(Volume(ct - AIR, subtracted=AIR)).data, tf.classify(Volume(ct)).data,
                               rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(tf.shifted(AIR).points[:, 0], [0.0, 1000.0, 1500.0])
    assert TransferFunction.preset("ct-bone").shifted(AIR).window == (0.0, 3000.0)
    grey = TransferFunction.preset("grey")  # "auto": the percentiles of the stored values, not shifted
    assert grey.shifted(AIR) is grey
    stored = ct - AIR
    np.testing.assert_array_equal(grey.classify(Volume(stored, subtracted=AIR)).data,
                                  grey.classify(Volume(stored)).data)
    # recorded in the input's units: the same window with or without the subtraction
    lo, hi = auto_window(ct)
    np.testing.assert_allclose(grey.resolved(Volume(ct - AIR, subtracted=AIR)).window, (lo, hi), rtol=1e-12)


def test_values_the_subtraction_would_merge_are_refused_naming_how_far_apart_to_set_them():
    """Points (or a window's ends) 1e-14 apart near 0 HU, shifted by subtracting -1000 to near 1000, where float64's
    spacing is 1.1e-13: one line naming the least distance that stays distinct (twice that spacing), not the
    "not increasing" of the merged points; set that far apart, they stay distinct."""
    grey = [(0.0, 0, 0, 0, 0.0), (1e-14, 1, 1, 1, 0.1), (1.0, 1, 1, 1, 0.1)]
    with pytest.raises(clwave.InputError, match=r"^transfer function values 0 and 1e-14 merge on the model's values, "
                                                r"stored as the input's minus the value subtracted, -1000; set them "
                                                r"at least 2\.3e-13 apart$"):
        TransferFunction(grey).shifted(AIR)
    with pytest.raises(clwave.InputError, match=r"^transfer function window 0 and 1e-14 merge .* 2\.3e-13 apart$"):
        TransferFunction.preset("hydrogen", window=(0.0, 1e-14)).shifted(AIR)
    apart = 2 * np.spacing(1000.0)
    assert np.all(np.diff(TransferFunction([grey[0], (apart, *grey[1][1:]), grey[2]]).shifted(AIR).points[:, 0]) > 0)
    assert np.diff(TransferFunction.preset("hydrogen", window=(0.0, apart)).shifted(AIR).window)[0] > 0


def test_nothing_visible_quotes_the_files_units():
    air = Volume(np.zeros((4, 4, 4)), subtracted=AIR)  # all air, stored as 0
    for check in (TransferFunction.preset("ct-bone").classify, TransferFunction.preset("ct-bone").check_visible):
        with pytest.raises(NothingVisibleError, match=r"span -1000 \.\. 2000 and the volume's values lie within "
                                                      r"-1000 \.\. -1000;"):
            check(air)


def test_the_value_subtracted_goes_through_the_model_and_its_file(tmp_path):
    vol = Volume(ct_in_hu() - AIR, subtracted=AIR)
    wv = clwave.WaveletVolume.from_volume(vol, "cubic", levels=1)
    assert wv.subtracted == AIR and wv.threshold(keep=0.5).subtracted == AIR and wv.reconstruct().subtracted == AIR
    path = wv.threshold(keep=0.5).save(tmp_path / "m.clw")
    assert clwave.WaveletVolume.open(path).subtracted == AIR
    chunked = Volume(da.from_array(vol.data, chunks=8), subtracted=AIR)
    model = clwave.WaveletVolume.from_volume(chunked, "cubic", levels=1)
    assert model.subtracted == AIR and model.threshold(keep=0.5).compute().subtracted == AIR
    assert clwave.WaveletVolume.open(model.save(tmp_path / "c.clw")).subtracted == AIR
    np.testing.assert_array_equal(  # chunked classification shifted as in memory
        TransferFunction.preset("ct-bone").classify(chunked).data.compute(),
        TransferFunction.preset("ct-bone").classify(vol).data)
    with h5py.File(path, "r+") as h5:  # the header's key is "offset", as in every file written since the fifteenth
        header = json.loads(h5.attrs["header"])  # session; a file written before it: its values are the input's
        assert header["offset"] == AIR and "subtracted" not in header
        del header["offset"]
        h5.attrs["header"] = json.dumps(header)
        h5.attrs["header_crc32"] = zlib.crc32(h5.attrs["header"].encode())
    assert clwave.WaveletVolume.open(path).subtracted == 0.0


def test_the_model_evaluates_the_stored_values():
    """evaluate and gradient give the stored values, the input's minus the value subtracted (their docstrings): an
    interpolating model at a voxel's centre is that voxel's stored value, 40 HU tissue stored as 1040."""
    vol = Volume(ct_in_hu() - AIR, subtracted=AIR)
    wv = clwave.WaveletVolume.from_volume(vol, "cubic", levels=1, interpolate=True)
    centres = vol.voxel_to_world(np.array([[1, 1, 1], [8, 10, 8], [4, 4, 4]]))
    np.testing.assert_allclose(wv.evaluate(centres)[:, 0], [1040.0, 1700.0, 0.0], atol=1e-2)
    h = 1e-3  # the gradient of the same stored values: central differences of evaluate
    steps = [(wv.evaluate(centres + h * e)[:, 0] - wv.evaluate(centres - h * e)[:, 0]) / (2 * h) for e in np.eye(3)]
    np.testing.assert_allclose(wv.gradient(centres)[:, 0], np.column_stack(steps), rtol=1e-4, atol=1e-2)


@pytest.mark.parametrize("value", [float("nan"), float("inf"), "-1000", True, [1.0]])
def test_a_hostile_value_subtracted_is_refused_in_one_line(tmp_path, capsys, value):
    path = clwave.WaveletVolume.from_volume(Volume(ct_in_hu()), "cubic", levels=1).save(tmp_path / "m.clw")
    with h5py.File(path, "r+") as h5:
        header = json.loads(h5.attrs["header"])
        header["offset"] = value
        h5.attrs["header"] = json.dumps(header)
        h5.attrs["header_crc32"] = zlib.crc32(h5.attrs["header"].encode())
    with pytest.raises(FileFormatError, match="offset") as err:
        clwave.WaveletVolume.open(path)
    assert "\n" not in str(err.value)
    code, _, err = run(capsys, "render", str(path), "--size", "8", "-o", str(tmp_path / "o.png"))
    assert code == 2 and err.count("\n") == 1 and "offset" in err, err
    assert not (tmp_path / "o.png").exists()


def _image(capsys, tmp_path, name, *argv):
    raw = tmp_path / f"{name}.npy"
    code, _, err = run(capsys, *argv, "--size", "12", "--raw", str(raw), "-o", str(tmp_path / f"{name}.png"),
                         "--force")
    assert code == 0, err
    return np.load(raw)


def test_subtract_and_a_ct_preset_on_the_command_line_pre_and_post_classified(ct_file, tmp_path, capsys):
    """--subtract -1000 --tf ct-bone: the same image as without --subtract, classified before the transform (splat,
    ray tracing) or while ray tracing (a scalar .clw with --classify post, or --tf given at render)."""
    common = ["--levels", "1", "--threshold", "0"]  # every coefficient
    for method in ("splat", "raytrace"):
        want = _image(capsys, tmp_path, "a", "render", str(ct_file), "--tf", "ct-bone", "--method", method, *common)
        got = _image(capsys, tmp_path, "b", "render", str(ct_file), "--tf", "ct-bone", "--method", method,
                     "--subtract", "-1000", *common)
        assert want[..., 3].max() > 0.1  # the bone core shows
        np.testing.assert_allclose(got, want, atol=1e-5)
    for name, extra in (("hu", []), ("shifted", ["--subtract", "-1000"])):
        code, _, err = run(capsys, "compress", str(ct_file), "--tf", "ct-bone", "--classify", "post", *common, *extra,
                           "-o", str(tmp_path / f"{name}.clw"))
        assert code == 0, err
        code, _, err = run(capsys, "compress", str(ct_file), *common, *extra, "-o", str(tmp_path / f"{name}-s.clw"))
        assert code == 0, err
    assert clwave.WaveletVolume.open(tmp_path / "shifted.clw").subtracted == AIR
    assert clwave.WaveletVolume.open(tmp_path / "shifted.clw").transfer_function["window"] == [-1000.0, 2000.0]
    want = _image(capsys, tmp_path, "c", "render", str(tmp_path / "hu.clw"), "--method", "raytrace")
    assert want[..., 3].max() > 0.1
    for argv in ([str(tmp_path / "shifted.clw")], [str(tmp_path / "shifted-s.clw"), "--tf", "ct-bone"]):
        got = _image(capsys, tmp_path, "d", "render", *argv, "--method", "raytrace")
        np.testing.assert_allclose(got, want, atol=1e-4)
    code, _, err = run(capsys, "render", str(tmp_path / "shifted-s.clw"), "--method", "raytrace", "--tf", "ct-bone",
                       "--tf-window", "1500,3000", "--size", "8", "-o", str(tmp_path / "e.png"))
    assert code == 2 and "span 1500 .. 3000" in err and "-1000 .. 7" in err, err  # the file's HU, not HU + 1000


def test_the_viewers_editor_shows_the_files_units():
    """A scalar model with a value subtracted in the viewer: the histogram behind the editor, and the window each
    frame carries (an "auto" one: the pool's percentiles), are in the input's units, the stored values plus the value
    subtracted; the final frame is clwave.raytrace with that window (given in the input's units)."""
    from test_view import BASE, decode, frames_until_final, run as run_async, socket_url

    import aiohttp

    from clwave.view import view

    wv = clwave.WaveletVolume.from_volume(Volume(clwave.phantom("hydrogen", 16).data, subtracted=-1.0), levels=1)

    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(socket_url(v))
            await ws.receive_json()
            texts = []
            await ws.send_str(json.dumps(dict(BASE, seq=1, mode="shaded")))
            return texts, await frames_until_final(ws, 1, texts=texts), v.server.sources["shaded"].tracer.scalar.sample
    with view(wv, size=24, tolerance=2e-2, tf=TransferFunction.preset("grey")) as v:
        texts, frames, sample = run_async(go(v))
    histogram = [t for t in texts if t["type"] == "histogram"][0]
    data = clwave.phantom("hydrogen", 16).data  # the histogram spans the input's range (raytracing.md §10)
    np.testing.assert_allclose(histogram["range"], [data.min() - 1.0, data.max() - 1.0], rtol=1e-6)
    np.testing.assert_allclose(histogram["field"], [sample.min() - 1.0, sample.max() - 1.0], rtol=1e-12)
    window = [w - 1.0 for w in auto_window(sample)]
    np.testing.assert_allclose(frames[-1][0]["tf_window"], window, rtol=1e-12)
    expect = clwave.raytrace(wv, clwave.Camera(30.0, 20.0, 24, extent=frames[-1][0]["extent"]), tolerance=2e-2,
                             transfer_function=TransferFunction.preset("grey", window=window))
    assert np.abs(decode(frames[-1][1]).astype(int) - expect.to_uint8(background=(0, 0, 0))).max() <= 1
