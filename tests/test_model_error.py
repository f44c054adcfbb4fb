"""The model's own error against its input, recorded by ``clwave compress`` in the ``.clw`` header (``model_error``,
docs/chunked.md §4) and shown by ``clwave info`` and the viewer's model line (docs/viewer.md §4)."""

import asyncio
import json
import sys
from pathlib import Path

import aiohttp
import h5py
import numpy as np
import pytest

import clwave
from clwave.cli import main
from clwave.errors import FileFormatError
from clwave.view import view
from test_hardening import crafted, setter

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
import browser  # noqa: E402  (tools/browser.py)

SHAPE = (14, 16, 18)


@pytest.fixture(scope="module")
def data():
    grid = np.indices(SHAPE).astype(np.float64)
    return (np.sin(grid[0] / 3) * np.cos(grid[1] / 4) + grid[2] / 20
            + np.random.default_rng(5).normal(0, 0.05, SHAPE)).astype(np.float32)


def compress(tmp_path, data, *extra, name="m.clw"):
    np.save(tmp_path / "v.npy", data)
    out = tmp_path / name
    assert main(["compress", str(tmp_path / "v.npy"), "--keep", "0.3", "-o", str(out), *extra]) == 0
    return out


def recorded(path):
    with h5py.File(path) as h5:
        return json.loads(h5.attrs["header"]).get("model_error")


def info(capsys, path, *argv):
    capsys.readouterr()  # what came before
    code = main(["info", str(path), *argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("quantise", [None, "2e-2"])
def test_compress_records_the_error_of_the_file_as_written(tmp_path, capsys, data, quantise):
    """The header's number is the RMS over the voxels of the file's model (reconstructed from the file as read back:
    a quantised one's rounded values) less the input, in float64, over the input's largest |value|; it is the number
    compress prints, and info gives it in text and JSON."""
    path = compress(tmp_path, data, *([] if quantise is None else ["--quantise", quantise]))
    printed = capsys.readouterr().out
    field = clwave.WaveletVolume.open(path).reconstruct().data.astype(np.float64)
    reference = data.astype(np.float64)
    expect = np.sqrt(np.mean((field - reference) ** 2)) / np.abs(reference).max()
    error = recorded(path)
    assert 1e-4 < expect < 0.5 and error == pytest.approx(expect, rel=1e-6)
    words = f"RMS over the voxels {expect:.2e} of the largest value (PSNR {-20 * np.log10(expect):.1f} dB)"
    # the data's noise (deviation 0.05) measured, and the error said in its units too (docs/model.md §2, noise)
    assert f"error                 {words}; " in printed and "times the input's noise (sigma 0.05" in printed, printed
    code, out, err = info(capsys, path)
    assert code == 0 and err == "" and f"error      {words}: the whole file's model against its input" in out, out
    code, out, _ = info(capsys, path, "--json")
    assert code == 0 and json.loads(out)["model_error"] == error


def test_the_quantised_files_error_is_its_own(tmp_path, capsys, data):
    """A coarse quantisation changes the model: the recorded error is the quantised file's, not the float model's."""
    plain = recorded(compress(tmp_path, data, name="plain.clw"))
    rounded = recorded(compress(tmp_path, data, "--quantise", "0.2", name="rounded.clw"))
    assert rounded != plain and abs(rounded - plain) > 1e-4 * plain


def test_no_error_is_recorded_where_none_was_measured(tmp_path, capsys, data):
    """An input read chunk by chunk ("not measured", as before), a model thresholded again from a .clw (another model:
    the parent's error is not its own), one written by the API: no key; info says "not recorded", JSON null."""
    path = compress(tmp_path, data)
    assert main(["compress", str(tmp_path / "v.npy"), "--chunks", "8", "-o", str(tmp_path / "chunked.clw")]) == 0
    assert "not measured: the input was read chunk by chunk" in capsys.readouterr().out
    assert main(["compress", str(path), "--keep", "0.1", "-o", str(tmp_path / "again.clw")]) == 0
    clwave.WaveletVolume.open(path, keep=0.1).save(tmp_path / "api.clw")
    for name in ("chunked.clw", "again.clw", "api.clw"):
        assert recorded(tmp_path / name) is None
        code, out, _ = info(capsys, tmp_path / name)
        assert code == 0 and "error      the model's error against its input not recorded" in out, out
        code, out, _ = info(capsys, tmp_path / name, "--json")
        assert code == 0 and json.loads(out)["model_error"] is None


def test_an_older_file_without_the_key_reads_as_not_recorded(tmp_path, capsys, data):
    path = compress(tmp_path, data)
    old = crafted(path, tmp_path, lambda header: header.pop("model_error"))
    assert clwave.WaveletVolume.open(old).kept == clwave.WaveletVolume.open(path).kept
    code, out, _ = info(capsys, old, "--json")
    assert code == 0 and json.loads(out)["model_error"] is None


@pytest.mark.parametrize("value", [-0.01, float("nan"), float("inf"), "0.1", True, [0.1], {"relative_rms": 0.1}])
def test_a_hostile_error_is_refused_in_one_line(tmp_path, capsys, data, value):
    path = crafted(compress(tmp_path, data), tmp_path, setter("model_error", value))
    with pytest.raises(FileFormatError) as exc:
        clwave.WaveletVolume.open(path)
    assert "model_error" in str(exc.value) and "\n" not in str(exc.value)
    code, out, err = info(capsys, path)
    assert code == 2 and out == "" and "model_error" in err and err.count("\n") == 1, err


def hello_of(source, **kw):
    async def go(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(v.url.replace("/?", "/ws?"))
            return await ws.receive_json()

    with view(source, size=(24, 24), **kw) as v:
        return asyncio.run(go(v))


def test_the_viewers_hello_carries_the_files_error(tmp_path, capsys, data):
    """The whole file: its error; fewer of its coefficients (keep): the whole file's error, said to be the file's; an
    older file: null; a model made in memory: no file's figure at all."""
    path = compress(tmp_path, data)
    error = recorded(path)
    assert hello_of(path)["model"]["error"] == dict(rms=error, whole=True)
    assert hello_of(path, keep=0.1)["model"]["error"] == dict(rms=error, whole=False)
    old = crafted(path, tmp_path, lambda header: header.pop("model_error"))
    assert hello_of(old)["model"]["error"] == dict(rms=None, whole=True)
    assert hello_of(clwave.WaveletVolume.open(path))["model"]["error"] is None


@pytest.mark.skipif(browser.executables() is None, reason=browser.SETUP)
def test_the_pages_model_line_gives_the_files_error(tmp_path, capsys, data):
    """In a headless browser: the whole file's error and PSNR as compress printed them (3 significant digits); a view
    keeping fewer of its coefficients says the error is the whole file's."""
    path = compress(tmp_path, data)
    printed = capsys.readouterr().out
    error = recorded(path)
    words = f"RMS {error:.3g} of the largest value (PSNR {-20 * np.log10(error):.1f} dB)"
    assert f"(PSNR {-20 * np.log10(error):.1f} dB)" in printed
    script = "const t = document.getElementById('model').textContent; return t.includes('error against') && t"
    for keep, tail in ((None, "; the frames' error"), (0.1, ", the whole file's; the frames' error")):
        with view(path, size=(24, 24), keep=keep) as v, browser.chromium() as page:
            browser.open_viewer(page, v.url)
            line = browser.wait_for(page, script)
        assert f". The model's error against the input: {words}{tail}" in line, line
