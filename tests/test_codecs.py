"""Quantised .clw values (docs/codecs.md): the voxel error bound against PyWavelets' own synthesis, files that
hold it, readers that check it, and tools/compare_codecs.py on a tiny volume."""

import importlib.util
import json
import shutil
import subprocess
import sys
from pathlib import Path

import dask.array as da
import h5py
import numpy as np
import pytest
import pywt

import clwave
from clwave.cli import main
from clwave.errors import FileFormatError, InputError
from clwave.io.clw import synthesis_bound
from clwave.model.bspline import wavelet_for

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def hydrogen():
    return clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", 24), "cubic", levels=2).threshold(keep=0.2)


def test_haar_synthesis_bound_is_the_closed_form():
    # Haar: at every level one coefficient of each band covers a voxel, with the value 2^(-3m/2)
    for levels in range(5):
        expected = 2.0 ** (-1.5 * levels) + sum(7 * 2.0 ** (-1.5 * m) for m in range(1, levels + 1))
        assert synthesis_bound(wavelet_for("haar"), levels) == pytest.approx(expected, rel=1e-12)


@pytest.mark.filterwarnings("ignore:Level value of .* is too high")  # expected on 12 voxels (CONVENTIONS.md)
@pytest.mark.parametrize("name", ["linear", "quadratic", "cubic"])
def test_synthesis_bound_is_the_sum_of_each_bands_largest_row_sum_of_pywavelets_synthesis(name):
    wavelet, shape = wavelet_for(name), (12, 12, 12)
    zero = pywt.wavedecn(np.zeros(shape), wavelet.pywt, mode="zero", level=1)
    total = 0.0
    for key in ["aaa"] + sorted(zero[1]):
        band = zero[0] if key == "aaa" else zero[1][key]
        rows = np.zeros(shape)
        for index in np.ndindex(band.shape):  # every coefficient of the band on its own: a column of synthesis
            coeffs = [np.zeros_like(zero[0]), {k: np.zeros_like(v) for k, v in zero[1].items()}]
            (coeffs[0] if key == "aaa" else coeffs[1][key])[index] = 1.0
            rows += np.abs(pywt.waverecn(coeffs, wavelet.pywt, mode="zero")[:12, :12, :12])
        total += rows.max()
    assert synthesis_bound(wavelet, 1) == pytest.approx(total, rel=1e-9)


@pytest.mark.parametrize("wavelet, interpolate", [("haar", False), ("cubic", False), ("cubic", True)])
@pytest.mark.parametrize("bound", [1e-3, 3e-2])
def test_quantised_file_moves_no_voxel_beyond_the_bound(tmp_path, wavelet, interpolate, bound):
    vol = clwave.phantom("marschner-lobb", 24)
    model = clwave.WaveletVolume.from_volume(vol, wavelet, levels=2, interpolate=interpolate).threshold(keep=0.1)
    model.save(tmp_path / "float.clw")
    model.save(tmp_path / "q.clw", quantise=bound)
    moved = np.abs(clwave.WaveletVolume.open(tmp_path / "q.clw").reconstruct().data - model.reconstruct().data)
    assert 0 < moved.max() <= bound
    assert (tmp_path / "q.clw").stat().st_size < (tmp_path / "float.clw").stat().st_size


def test_auto_step_is_half_the_smallest_stored_detail(tmp_path, hydrogen):
    hydrogen.save(tmp_path / "q.clw", quantise="auto")
    g = hydrogen.groups[0]
    details = np.abs(g.values[0, g.band_slices()[0].stop:])
    with h5py.File(tmp_path / "q.clw") as h5:
        q, step = h5["g0/values"][...], h5["g0/values"].attrs["step"]
    assert q.dtype == np.int32
    assert step == pytest.approx(0.5 * details[details > 0].min())
    back = clwave.WaveletVolume.open(tmp_path / "q.clw").groups[0]
    stored = np.isin(g.positions, back.positions)
    assert np.all(stored[g.band_slices()[0].stop:])  # no detail rounds to zero
    assert np.all(np.abs(g.values[0, ~stored]) <= 0.5 * step)  # what is left out rounds to zero
    assert np.abs(back.values - g.values[:, stored]).max() <= 0.5 * step * (1 + 1e-6)  # a rounding, no more


def test_quantised_prefix_read_equals_thresholding_the_whole_file(tmp_path, hydrogen):
    hydrogen.save(tmp_path / "q.clw", quantise="auto")
    whole = clwave.WaveletVolume.open(tmp_path / "q.clw")
    assert np.all(whole.groups[0].values != 0)  # what rounds to zero is not stored
    for keep in (0.01, 0.05):
        part, expected = clwave.WaveletVolume.open(tmp_path / "q.clw", keep=keep), whole.threshold(keep=keep)
        # rounded values tie often: the same importances are kept, not always the same of equal ones
        np.testing.assert_array_equal(np.sort(part.importance(part.groups[0])),
                                      np.sort(expected.importance(expected.groups[0])))


def test_streamed_quantised_file_equals_the_in_memory_file(tmp_path, rng):
    data = rng.random((20, 18, 22), dtype=np.float32)
    chunked = clwave.Volume(da.from_array(data, chunks=(7, 9, 8)))
    clwave.WaveletVolume.from_volume(data, "cubic", levels=2).threshold(keep=0.3).save(tmp_path / "m.clw",
                                                                                       quantise=1e-3)
    clwave.WaveletVolume.from_volume(chunked, "cubic", levels=2).threshold(keep=0.3).save(tmp_path / "c.clw",
                                                                                          quantise=1e-3)
    with h5py.File(tmp_path / "m.clw") as a, h5py.File(tmp_path / "c.clw") as b:
        for name in ("g0/positions", "g0/values", "g0/runs", "content_mask"):
            np.testing.assert_array_equal(a[name][...], b[name][...])
    with pytest.raises(InputError, match="a bound"):
        clwave.WaveletVolume.from_volume(chunked, "cubic", levels=2).threshold(keep=0.3).save(tmp_path / "a.clw",
                                                                                              quantise="auto")


@pytest.mark.parametrize("quantise", [0, -1e-3, float("nan"), float("inf"), "fine", [1e-3], True])
def test_bad_bounds_are_refused_before_writing(tmp_path, hydrogen, quantise):
    with pytest.raises(InputError, match="must be a bound > 0") as err:
        hydrogen.save(tmp_path / "q.clw", quantise=quantise)
    assert "\n" not in str(err.value) and not (tmp_path / "q.clw").exists()


def test_a_bound_too_small_for_32_bits_is_refused(tmp_path, hydrogen):
    with pytest.raises(InputError, match="fit in 32 bits"):
        hydrogen.save(tmp_path / "q.clw", quantise=1e-12)


@pytest.mark.parametrize("change, needle", [
    (lambda d: d.attrs.__setitem__("step", -0.5), "quantisation step"),
    (lambda d: d.attrs.__setitem__("step", np.nan), "quantisation step"),
    (lambda d: d.attrs.__setitem__("step", "0.1"), "quantisation step"),
    (lambda d: d.attrs.__setitem__("step", np.array([0.1, 0.2])), "quantisation step of shape"),
    (lambda d: d.attrs.__setitem__("step", np.zeros(1 << 20)), "attribute 'step' of float type and 8,388,608"),
    (lambda d: d.attrs.__setitem__("step", np.int64(2)), "quantisation step of shape"),
    (lambda d: d.attrs.__delitem__("step"), "expected .* float32"),
    (lambda d: d.attrs.__setitem__("step", 1e300), "non-finite"),
])
def test_reader_refuses_bad_quantisation(tmp_path, hydrogen, change, needle):
    hydrogen.save(tmp_path / "q.clw", quantise="auto")
    with h5py.File(tmp_path / "q.clw", "r+") as h5:
        change(h5["g0/values"])
    with pytest.raises(FileFormatError, match=needle) as err:
        clwave.WaveletVolume.open(tmp_path / "q.clw")
    assert "\n" not in str(err.value)


def test_a_bound_that_rounds_every_value_to_zero_keeps_nothing(tmp_path, hydrogen):
    """Nothing left to store is an empty file of the model, not a crash."""
    hydrogen.save(tmp_path / "z.clw", quantise=1e9)
    assert clwave.WaveletVolume.open(tmp_path / "z.clw").kept == 0
    empty = clwave.WaveletVolume.from_volume(clwave.Volume(np.zeros((8, 8, 8), np.float32)), levels=1)
    empty.save(tmp_path / "e.clw")
    assert clwave.WaveletVolume.open(tmp_path / "e.clw").kept == 0


def test_reader_refuses_a_float_file_with_a_step(tmp_path, hydrogen):
    hydrogen.save(tmp_path / "f.clw")
    shutil.copy(tmp_path / "f.clw", tmp_path / "g.clw")
    with h5py.File(tmp_path / "g.clw", "r+") as h5:
        h5["g0/values"].attrs["step"] = 0.5
    with pytest.raises(FileFormatError, match="expected .* int32"):
        clwave.WaveletVolume.open(tmp_path / "g.clw")
    clwave.WaveletVolume.open(tmp_path / "f.clw")  # the float file itself reads


def test_compress_quantise_reports_the_error_of_the_file(tmp_path, capsys):
    out = tmp_path / "m.clw"
    assert main(["compress", "phantom:marschner-lobb:24", "--levels", "2", "--quantise", "auto", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    stored = clwave.WaveletVolume.open(out).reconstruct().data
    truth = clwave.phantom("marschner-lobb", 24).data
    psnr = 20 * np.log10(np.abs(truth).max() / np.sqrt(np.mean((stored - truth) ** 2)))
    assert f"(PSNR {psnr:.1f} dB)" in text
    assert main(["compress", "phantom:hydrogen:16", "--quantise", "tiny", "-o", str(tmp_path / "x.clw")]) == 2
    err = capsys.readouterr().err
    assert "--quantise tiny must be a bound > 0" in err and err.count("\n") == 1


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("matplotlib") is None, reason="matplotlib (the test extra) is missing")
def test_compare_codecs_end_to_end(tmp_path):
    proc = subprocess.run([sys.executable, str(ROOT / "tools" / "compare_codecs.py"), "--size", "24", "--volumes",
                           "hydrogen", "shepp-logan", "--keep", "0.005", "0.05", "0.2", "--out", str(tmp_path),
                           "--figure", str(tmp_path / "rd.png")], cwd=ROOT, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = json.loads((tmp_path / "rate_distortion.json").read_text())
    for volume in ("hydrogen", "shepp-logan"):
        rows = [r for r in report["rows"] if r["volume"] == volume]
        clw = {(r["codec"], r["keep"]): r for r in rows if r["codec"].startswith(".clw")}
        for codec in (".clw float", ".clw quantised"):
            assert clw[(codec, 0.2)]["psnr"] > clw[(codec, 0.005)]["psnr"]
            assert clw[(codec, 0.2)]["xray_error"] < clw[(codec, 0.005)]["xray_error"]
        for keep in (0.005, 0.05, 0.2):
            assert clw[(".clw quantised", keep)]["bits_per_voxel"] < clw[(".clw float", keep)]["bits_per_voxel"]
        for r in rows:  # sizes are the bytes written; errors as measured here from the decoded voxels
            assert r["bits_per_voxel"] == pytest.approx(8 * r["bytes"] / 24 ** 3)
            assert np.isfinite(r["psnr"]) and r["rmse"] > 0
        names = {r["codec"] for r in rows}
        if importlib.util.find_spec("zfpy"):
            assert {"zfp fixed-rate", "zfp fixed-accuracy"} <= names
        if importlib.util.find_spec("pysz"):
            assert "SZ3" in names
    assert (tmp_path / "rd.png").stat().st_size > 0 and "| hydrogen |" in (tmp_path / "rate_distortion.md").read_text()
