"""Untrusted files and outputs: crafted .clw headers, racing writers, full disks, signals."""

import errno
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
import zlib
from pathlib import Path

import h5py
import numpy as np
import pytest

import clwave
from clwave.errors import FileFormatError, InputError, OutputError, OutputExistsError
from clwave.io.files import write_atomic

ROOT = Path(__file__).resolve().parents[1]


def crafted(model_file, tmp_path, edit=None, change=None) -> Path:
    """A copy of ``model_file`` whose header ``edit`` changed, or that ``change(h5 file)`` changed."""
    out = tmp_path / "crafted.clw"
    shutil.copy(model_file, out)
    with h5py.File(out, "r+") as h5:
        if edit is not None:
            header = json.loads(h5.attrs["header"])
            edit(header)
            if "version" in header:  # an attribute of its own
                h5.attrs["version"] = header.pop("version")
            h5.attrs["header"] = json.dumps(header)
            h5.attrs["header_crc32"] = zlib.crc32(h5.attrs["header"].encode())  # a consistent forgery
        if change is not None:
            change(h5)
    return out


def setter(key, value):
    return lambda header: header.__setitem__(key, value)


@pytest.mark.parametrize("edit, needle", [
    (setter("shape", [2048, 2048, 2048]), "expected (2048, 2048, 2048)"),
    (setter("shape", [100000, 100000, 100000]), "expected (100000, 100000, 100000)"),
    (setter("shape", [-16, 16, 16]), "shape"),
    (setter("shape", [16, 16]), "shape"),
    (setter("groups", []), "no channel groups"),
    (setter("channels", 3), "channels"),
    (setter("spacing", [0, 1, 1]), "spacing"),
    (setter("spacing", [float("nan"), 1, 1]), "spacing"),
    (setter("origin", [float("inf"), 0, 0]), "origin"),
    (setter("levels", 9), "levels"),
    (setter("version", 99), "format version 99"),
    (lambda h: h["groups"][0].__setitem__("wavelet", 7), "wavelet order"),
    (setter("focus", []), "focus [] is not"),
    (setter("focus", [[1, 2, 3]]), "focus [[1, 2, 3]] is not"),
    (setter("focus", [[float("nan"), 0, 0], 1]), "focus [[nan, 0, 0], 1] is not"),
    (setter("focus", [[0, 0, 0], 0]), "sigma > 0"),
    (setter("content", [1]), "content [1] is not"),
    (setter("content", [[1, 0, 0], [0, 1, 1]]), "low below high"),
    (setter("content", [[1, 1, 1], [1, 1, 1]]), "low below high"),  # an empty box: the fits divided by its size
    (setter("transfer_function", [1, 2]), "transfer function is not valid"),
    (setter("interpolate", "yes"), "interpolate 'yes' is not true or false"),
    (setter("obliquity", -1), "obliquity -1 is not one number of degrees from 0 to 90"),
    (setter("obliquity", "20"), "obliquity '20' is not"),
    (setter("obliquity", float("nan")), "obliquity nan is not"),
    (setter("unit", "furlong"), "unit 'furlong' is not one of m, cm, mm, um"),
    # JSON numbers of the wrong kind: a float channel index passed the groups' check, and failed as an index later
    (lambda h: h["groups"][0].__setitem__("channels", [0.0]), "list of channel numbers"),
    (setter("levels", True), "levels True is not possible"),
    (setter("channels", True), "channels True is not"),
    # a content box beyond the volume's box: the renderers' planes and bounds overflowed (harden20's fuzzing)
    (setter("content", [[0, 0, 0], [1e308, 1e308, 1e308]]), "reaches outside the volume's box"),
    (setter("content", [[-100, -100, -100], [-90, -90, -90]]), "reaches outside the volume's box"),
    (setter("spacing", [1e-308, 1, 1]), "outside the world lengths clwave renders"),  # the splatter divided by 0
    (setter("origin", [1e308, 0, 0]), "outside the world lengths clwave renders"),
])
def test_crafted_clw_headers_are_refused_before_anything_is_allocated(model_file, tmp_path, edit, needle):
    path = crafted(model_file, tmp_path, edit)
    start = time.process_time()  # CPU seconds: the work before the refusal, whatever the load (wall-clock ones failed)
    with pytest.raises(FileFormatError) as err:
        clwave.WaveletVolume.open(path)
    assert needle in str(err.value) and "\n" not in str(err.value)
    assert time.process_time() - start < 1.0


def test_a_header_without_its_optional_properties_opens(model_file, tmp_path):
    """focus, content and transfer_function may be absent (None), as the header's check says: read_clw took focus
    as a required key (a KeyError, an internal error on the command line; harden20's fuzzing)."""
    def strip(header):
        for key in ("focus", "content", "transfer_function"):
            header.pop(key)

    wv = clwave.WaveletVolume.open(crafted(model_file, tmp_path, strip))
    assert wv.focus is None and wv.content is None and wv.transfer_function is None
    wv = clwave.WaveletVolume.open(crafted(model_file, tmp_path, lambda header: header.pop("unit")))
    assert wv.unit is None  # a file of before session 19 records no world unit: unknown


def test_other_files_named_clw_are_refused(tmp_path):
    npy = tmp_path / "x.clw"
    np.save(tmp_path / "x.npy", np.zeros(8))
    (tmp_path / "x.npy").rename(npy)
    with pytest.raises(FileFormatError, match="cannot read"):
        clwave.WaveletVolume.open(npy)
    other = tmp_path / "other.clw"
    with h5py.File(other, "w") as h5:
        h5["data"] = np.zeros(8)
    with pytest.raises(FileFormatError, match="not a clwave wavelet volume"):
        clwave.WaveletVolume.open(other)


def test_a_version_1_file_is_named_as_such(tmp_path):
    old = tmp_path / "old.clw"
    with open(old, "wb") as fh:  # version 1 was a zip of .npy members
        np.savez_compressed(fh, header=np.frombuffer(b'{"version": 1}', np.uint8))
    with pytest.raises(FileFormatError, match="format version 1.*compress the volume again"):
        clwave.WaveletVolume.open(old)


def _approximation_in_the_details(h5):
    """The approximation's first position moved to the first detail band's (a position of the group)."""
    from clwave.model.bspline import SplineWavelet
    from clwave.model.transform import band_layout

    header = json.loads(h5.attrs["header"])
    n_approx = band_layout(SplineWavelet(header["groups"][0]["wavelet"]), header["shape"], header["levels"])[0].size
    runs = h5["g0/runs"][...]
    h5["g0/positions"][runs[runs[:, 0] == -1][0, 1]] = n_approx  # a run's first difference is its first position


def _unwritten_mask(h5):
    """The content mask replaced by a dataset of the same shape whose chunks were never written: reading it
    would allocate for data the file does not hold."""
    old = h5["content_mask"]
    shape, chunks = old.shape, old.chunks
    del h5["content_mask"]
    h5.create_dataset("content_mask", shape=shape, dtype=np.uint8, chunks=chunks, compression="gzip")


@pytest.mark.parametrize("change, needle", [
    (lambda h5: h5.__delitem__("g0/runs"), "missing"),
    (_unwritten_mask, "stores 0 of its 1 chunks"),
    (_approximation_in_the_details, "outside its bands"),
    (lambda h5: h5["g0/runs"].__setitem__((0, 2), 10 ** 9), "do not tile"),
    (lambda h5: h5["g0/positions"].__setitem__(0, -5), "outside its bands"),
    (lambda h5: h5["g0/values"].__setitem__((0, 0), np.nan), "non-finite"),
])
def test_crafted_clw_members_are_refused(model_file, tmp_path, change, needle):
    with pytest.raises(FileFormatError, match=needle) as err:
        clwave.WaveletVolume.open(crafted(model_file, tmp_path, change=change))
    assert "\n" not in str(err.value)


def test_an_empty_run_where_another_starts_is_read(model_file, tmp_path):
    """The writer ends a tier of whole chunks with a run of no rows, which starts where the next run does:
    the runs still tile the rows, whichever order the table lists them in."""
    def empty_run_after_its_peer(h5):
        runs = h5["g0/runs"][...]
        del h5["g0/runs"]
        h5["g0/runs"] = np.vstack([runs, [runs[-1, 0], runs[0, 1], 0]])
    back = clwave.WaveletVolume.open(crafted(model_file, tmp_path, change=empty_run_after_its_peer))
    whole = clwave.WaveletVolume.open(model_file)
    assert np.array_equal(back.groups[0].all_positions(), whole.groups[0].all_positions())
    assert np.array_equal(back.groups[0].values, whole.groups[0].values)


def test_a_model_beyond_memory_is_named_with_the_way_out(model_file, monkeypatch):
    from clwave.io import clw

    def no_memory(shape):
        raise MemoryError
    monkeypatch.setattr(clw, "FileMask", lambda path, shape: no_memory(shape))
    with pytest.raises(InputError, match="more than this machine's memory.*keep"):
        clwave.WaveletVolume.open(model_file)


def test_a_flipped_bit_in_the_header_fails_its_checksum(model_file, tmp_path):
    def flip(h5):
        h5.attrs["header"] = h5.attrs["header"].replace('"levels": 1', '"levels": 0')  # still valid
    with pytest.raises(FileFormatError, match="does not match its checksum"):
        clwave.WaveletVolume.open(crafted(model_file, tmp_path, change=flip))


@pytest.mark.parametrize("levels", [0, 1])
def test_voxels_near_the_float32_limit_are_refused_not_rendered(levels):
    """At 0 levels too (the model is the voxels, finite, but a splat of 3e38 through 8 voxels was inf): the model is
    at most its largest voxel, so a line integral is at most that times the diagonal (13.9 for 8^3), which must stay
    below 1.8e19, the root of float32's largest value, so that the energies (sums of squares) of images are finite
    too (a NIfTI's scl_slope of 1e30 gave inf energies, numpy's overflow warnings and an inf error, exit 0)."""
    data = np.full((8, 8, 8), 3.0e38, np.float32)
    with pytest.raises(InputError, match=r"line integrals of this volume overflow float32 once squared \(its largest "
                                         r"value 3e\+38 times its diagonal 13.9 passes 1.8e19"):
        clwave.WaveletVolume.from_volume(data, "cubic", levels=levels)
    with pytest.raises(InputError, match="its diagonal 1.39e\\+18 passes 1.8e19.*or its spacing"):
        clwave.WaveletVolume.from_volume(clwave.Volume(np.full((8, 8, 8), 100.0), spacing=1e17), "cubic", levels=levels)
    with pytest.raises(InputError, match=r"its largest value 1.4e\+18 times its diagonal 13.9 passes 1.8e19"):
        clwave.WaveletVolume.from_volume(np.full((8, 8, 8), 1.4e18, np.float32), "cubic", levels=levels)
    huge = clwave.WaveletVolume.from_volume(np.full((8, 8, 8), 1.3e18, np.float32), "cubic", levels=levels)
    image = clwave.splat(huge, clwave.Camera(0, 0, size=8)).image  # 1.3e18 x 13.9 = 1.8e19: taken, finite
    assert np.isclose(image.max(), 8 * 1.3e18, rtol=1e-3)  # the constant's integral through 8 unit voxels
    # a thin volume: its integrals are small, but the ray tracer's quadrature sums 12 samples' worth (Simpson's pair)
    thin = clwave.Volume(np.full((8, 8, 8), 1.6e18, np.float32), spacing=1e-3)  # 1.6e18 x 12 passes 1.8e19
    with pytest.raises(InputError, match=r"1.6e\+18 times the ray tracer's quadrature weights 12 \(its diagonal is"):
        clwave.WaveletVolume.from_volume(thin, "cubic", levels=levels)
    taken = clwave.WaveletVolume.from_volume(clwave.Volume(np.full((8, 8, 8), 1.5e18, np.float32), spacing=1e-3),
                                             "cubic", levels=levels)
    traced = clwave.raytrace(taken, clwave.Camera(0, 0, size=8), absorption=False).image
    assert np.all(np.isfinite(traced)) and np.isclose(traced.max(), 8e-3 * 1.5e18, rtol=1e-2)


def test_frames_of_line_integrals_near_the_bound_have_finite_errors():
    """Line integrals up to 1.8e19 are taken (above): their squares are finite one by one, not summed in float32, so
    a frame's estimate (the step from the frame before) and its measured errors sum them in float64 (an 8^2 step of
    1e19 gave inf)."""
    from clwave.frames import ErrorEstimate, FinalImage, Frame

    final = np.full((8, 8, 1), 1.8e19, np.float32)
    first = np.zeros_like(final)
    steps = ErrorEstimate()
    steps.add(first)
    assert steps.add(final) == pytest.approx((1.0, 1.0))  # relative RMS and max of the step
    frame = Frame(0, first, 0.0, 1.0, 1.0, _final=FinalImage(lambda: final))
    figures = frame.figures()
    assert frame.rms_error == pytest.approx(1.8e19, rel=1e-6) and figures["relative_rms_error"] == pytest.approx(1.0)


def test_a_huge_nifti_scale_is_refused_before_anything_is_written(tmp_path, capsys):
    """A NIfTI whose scl_slope makes its values 2.5e32 (within float32's range): refused in one line before the
    file is written (was written, with numpy's overflow warnings and "RMS ... inf (PSNR -inf dB)", exit 0); the
    largest scale taken reports a finite error (its squares measured relative to the largest value)."""
    import nibabel as nib
    from clwave.cli import main

    data = np.random.default_rng(0).integers(0, 256, (12, 12, 12), dtype=np.uint8)
    for slope, code in ((1e30, 2), (2e15, 0)):  # 255 x 2e15 x the diagonal 20.8 = 1.1e19, below 1.8e19
        image = nib.Nifti1Image(data, np.eye(4))
        image.header.set_slope_inter(slope, 0.0)
        nib.save(image, tmp_path / "v.nii")
        argv = ["compress", str(tmp_path / "v.nii"), "--levels", "0", "-o", str(tmp_path / f"{code}.clw")]
        assert main(argv) == code  # filterwarnings=error: no numpy warning either
        out, err = capsys.readouterr()
        assert (tmp_path / f"{code}.clw").exists() == (code == 0)
        if code:
            assert err.startswith("clwave: error: the line integrals of this volume overflow float32 once squared ("
                                  "its largest value 2.55e+32") and err.count("\n") == 1
        else:
            assert "RMS over the voxels" in out and "inf" not in out and "nan" not in out


def test_coefficients_whose_squares_overflow_are_refused():
    """A wavelet coefficient's square must be finite in float32 too (the energies that threshold a model and estimate
    its error sum them): refused past 1.8e19, the root of 3.4e38, as the transform's own overflow is."""
    from clwave.model.transform import check_coefficients

    check_coefficients(np.array([1.8e19, -1.8e19], np.float32))
    with pytest.raises(InputError, match=r"^the energies of this volume overflow float32 \(its largest wavelet "
                                         r"coefficient 1.9e\+19 squared passes 3.4e38\); rescale"):
        check_coefficients(np.array([1.0, -1.9e19], np.float32))


def test_a_damaged_chunk_fails_its_checksum(model_file, tmp_path):
    out = tmp_path / "damaged.clw"
    shutil.copy(model_file, out)
    with h5py.File(out, "r") as h5:
        offset = h5["g0/values"].id.get_chunk_info(0).byte_offset
    data = bytearray(out.read_bytes())
    data[offset + 20] ^= 0xFF
    out.write_bytes(bytes(data))
    with pytest.raises(FileFormatError, match="cannot read .*corrupt"):
        clwave.WaveletVolume.open(out)


def test_two_writers_racing_for_one_name_one_wins(tmp_path):
    target, results = tmp_path / "out.bin", []
    barrier = threading.Barrier(2)

    def write(tag):
        def writer(fh):
            fh.write(tag * 1000)
            barrier.wait()  # both are written, neither is published yet
        try:
            write_atomic(target, writer)
            results.append(tag)
        except OutputExistsError:
            results.append(b"refused")

    threads = [threading.Thread(target=write, args=(tag,)) for tag in (b"a", b"b")]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(results)[-1] == b"refused" and len(results) == 2
    winner = [r for r in results if r != b"refused"][0]
    assert target.read_bytes() == winner * 1000 and sorted(p.name for p in tmp_path.iterdir()) == ["out.bin"]


@pytest.mark.parametrize("failure", [OSError(errno.ENOSPC, "No space left on device"),
                                     PermissionError(errno.EACCES, "Permission denied")])
def test_disk_and_permission_errors_are_one_line_and_leave_nothing(tmp_path, failure):
    def writer(fh):
        fh.write(b"half")
        raise failure
    with pytest.raises(OutputError) as err:
        write_atomic(tmp_path / "out.png", writer)
    assert failure.strerror in str(err.value) and "\n" not in str(err.value)
    assert not list(tmp_path.iterdir())


def test_non_finite_images_are_never_written(tmp_path):
    result = clwave.RenderResult(np.array([[[1.0], [np.nan]]], np.float32), {"method": "splat"})
    for name in ("x.png", "x.npy"):
        with pytest.raises(InputError, match="non-finite"):
            result.save(tmp_path / name)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("signum, code", [(signal.SIGTERM, 143), (signal.SIGKILL, -9)])
def test_a_signal_while_writing_leaves_nothing(tmp_path, signum, code):
    script = f"""
import sys, time
from clwave import cli
from clwave.io import clw
def slow(model, fh, *_):
    fh.write(b"partial")
    fh.flush()
    print("writing", flush=True)
    time.sleep(60)
clw._write = slow
sys.exit(cli.main(["compress", "phantom:hydrogen:16", "--levels", "1", "-o", {str(tmp_path / 'out.clw')!r}]))
"""
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env=dict(os.environ, PYTHONPATH=str(ROOT)))
    while b"writing" not in proc.stdout.readline():  # the file is being written
        assert proc.poll() is None
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == code and (signum == signal.SIGKILL or b"terminated" in err)
    assert not list(tmp_path.iterdir())  # an unnamed file dies with its process, even killed


def test_a_member_declaring_more_than_the_header_allows_is_not_decompressed(model_file, tmp_path):
    def bomb(h5):  # 200 MB of zeros deflate to ~200 KB
        del h5["g0/values"]
        h5.create_dataset("g0/values", data=np.zeros((50_000_000, 1), np.float32), chunks=(1 << 20, 1),
                          compression="gzip")
    path = crafted(model_file, tmp_path, change=bomb)
    assert path.stat().st_size < 1_000_000
    start = time.process_time()
    with pytest.raises(FileFormatError, match="expected"):
        clwave.WaveletVolume.open(path)
    assert time.process_time() - start < 1.0


@pytest.mark.parametrize("suffix", [".nii", ".nii.gz"])
def test_a_nifti_header_that_lies_about_its_size_is_refused_before_reading(tmp_path, suffix):
    import gzip

    import nibabel
    small = tmp_path / "small.nii"
    nibabel.save(nibabel.Nifti1Image(np.ones((2, 2, 2), np.float32), np.eye(4)), small)
    raw = bytearray(small.read_bytes())
    raw[42:48] = np.array([1200, 1200, 1200], "<i2").tobytes()  # dim[1..3] of the NIfTI-1 header
    liar = tmp_path / ("liar" + suffix)
    liar.write_bytes(gzip.compress(bytes(raw)) if suffix == ".nii.gz" else bytes(raw))
    start = time.process_time()
    with pytest.raises(FileFormatError, match="1200 x 1200 x 1200 voxels"):
        clwave.load(liar)
    assert time.process_time() - start < 1.0


@pytest.mark.parametrize("call, name", [
    (lambda: clwave.Camera(extent="wide"), "extent"),
    (lambda: clwave.Camera(fov="30"), "fov"),
    (lambda: clwave.Camera(distance=[1, 2]), "distance"),
    (lambda: clwave.load(42), "path"),
    (lambda: clwave.Volume([[[1.0, 2.0], [3.0]]]), "rectangular"),
    (lambda: clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", 8), levels=1).threshold(keep="5%"), "keep"),
    (lambda: clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", 8), levels=1).threshold(threshold=None,
                                                                                                   keep=[0.1]), "keep"),
])
def test_api_misuse_raises_a_standard_exception_naming_the_argument(call, name):
    with pytest.raises((TypeError, ValueError)) as err:
        call()
    assert name in str(err.value) and "\n" not in str(err.value)


def test_an_unexpected_exception_is_one_line_that_says_it_is_a_bug(monkeypatch, capsys):
    from clwave import cli

    def broken(args):
        raise RuntimeError("something nobody foresaw")

    monkeypatch.setattr(cli.info, "run", broken)
    assert cli.main(["info"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "bug" in err and "something nobody foresaw" in err and "--debug" in err
    with pytest.raises(RuntimeError):
        cli.main(["--debug", "info"])


def test_options_that_do_not_apply_to_a_phantom_are_errors(tmp_path, capsys):
    from clwave.cli import main
    for option in (["--series", "3"], ["--dtype", "uint16"], ["--hu-to-mu"]):
        assert main(["compress", "phantom:hydrogen:16", *option, "-o", str(tmp_path / "x.clw")]) == 2
        assert option[0] in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


@pytest.fixture(scope="module")
def splat_kernels(tmp_path_factory):
    """The splatting kernels built in this process: with an empty PoCL cache (CI's) their first build is seconds, tens
    on a loaded machine, and a refusal made after it (the texel pool's) would be timed with it."""
    from clwave.cli import main
    assert main(["render", "phantom:hydrogen:16", "--levels", "1", "--size", "8", "-o",
                 str(tmp_path_factory.mktemp("kernels") / "x.png")]) == 0


@pytest.mark.parametrize("option, needle", [
    (["--extent", "1e12"], "render more pixels (--size)"),  # textures filtered by a pixel of 1e11 voxels
    (["--omega-s", "nan"], "--omega-s"),
    (["--omega-s", "1e4"], "footprint textures"),  # the largest band taken (1e9: refused as past it, test_attack28)
    (["--spacing", "1e-6,1,1e6"], "footprint textures"),
    (["--extent", "-1"], "--extent"),
])
def test_extreme_geometry_is_one_line_before_any_texture_is_made(splat_kernels, tmp_path, capsys, option, needle):
    """One error line; a spacing that makes a needle of the box (1.6e7 x 16 x 1.6e-5) has the needle's warning
    before it, naming --spacing (trial26)."""
    from clwave.cli import main
    start = time.perf_counter()
    code = main(["render", "phantom:hydrogen:16", "--levels", "1", *option, "-o", str(tmp_path / "x.png")])
    *warned, err = capsys.readouterr().err.splitlines()
    assert code == 2 and err.startswith("clwave: error: ") and needle in err and not list(tmp_path.iterdir())
    needle_warning = "clwave: warning: the content's box is 1.6e+07 x 16 x 1.6e-05 (x, y, z), 1e+06 times longer"
    assert [w[:len(needle_warning)] for w in warned] == ([needle_warning] if option[0] == "--spacing" else [])
    assert time.perf_counter() - start < 10


def test_an_extreme_zoom_renders_from_textures_of_the_band(tmp_path):
    """``--extent 1e-6`` (a millionth of a voxel): splatting's textures stop at the band's texel (docs/splatting.md
    §2, magnified views), so the view is drawn rather than refused or left building textures for ever: every pixel
    is the model's line integral along the ray through the view's centre, integrated here from ``evaluate`` (the
    magnified images' accuracy elsewhere: tests/test_splat.py).  The time bound is a hang's, loose under load."""
    from clwave.cli import main
    start = time.perf_counter()
    out, raw = tmp_path / "x.png", tmp_path / "x.npy"
    assert main(["render", "phantom:hydrogen:16", "--levels", "1", "--threshold", "0", "--extent", "1e-6",
                 "--size", "8", "-o", str(out), "--raw", str(raw)]) == 0
    assert out.exists() and time.perf_counter() - start < 120
    image = np.load(raw)[..., 0]
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", 16), levels=1)  # every coefficient
    view = clwave.Camera(size=8, extent=1e-6).view(wv)
    t = np.linspace(-40.0, 40.0, 160001)  # past the model's support (B-splines reach 2 voxels beyond the faces)
    exact = np.trapezoid(wv.evaluate(view.target + t[:, None] * view.n)[:, 0], t)
    assert np.all(np.isfinite(image)) and exact > 0.5
    np.testing.assert_allclose(image, exact, rtol=2e-3)


@pytest.mark.parametrize("argv, needle", [
    (["compress", "phantom:hydrogen:100000"], "choose a smaller N"),
    (["compress", "phantom:hydrogen:5000"], "GiB available"),
    (["progressive", "phantom:hydrogen:16", "--steps", "100000"], "--steps 100000"),
])
def test_absurd_work_is_refused_up_front(tmp_path, capsys, argv, needle):
    from clwave.cli import main
    out = tmp_path / ("x.gif" if argv[0] == "progressive" else "x.clw")
    start = time.process_time()
    assert main([*argv, "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1 and time.process_time() - start < 5
    with pytest.raises(MemoryError, match="choose a smaller n"):  # the API too, before allocating
        clwave.phantom("hydrogen", 100000)


def test_float64_values_beyond_float32_are_named_without_a_warning(tmp_path):
    data = np.ones((4, 4, 4))
    data[1, 2, 3] = 1e300
    np.save(tmp_path / "big.npy", data)
    with pytest.raises(InputError, match="beyond float32's range"):  # filterwarnings=error: no overflow warning
        clwave.load(tmp_path / "big.npy")


def test_a_cut_tiff_stack_is_one_line_on_the_command_line(tmp_path):
    import tifffile
    tifffile.imwrite(tmp_path / "stack.tif", np.arange(8 * 32 * 32, dtype=np.uint16).reshape(8, 32, 32))
    data = (tmp_path / "stack.tif").read_bytes()
    (tmp_path / "cut.tif").write_bytes(data[:len(data) // 2])
    proc = subprocess.run([sys.executable, "-m", "clwave", "compress", str(tmp_path / "cut.tif"), "--spacing", "1",
                           "-o", str(tmp_path / "c.clw")], cwd=ROOT, capture_output=True, text=True, timeout=120,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))  # a process of its own: no log capture
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "truncated or corrupt" in proc.stderr


@pytest.mark.parametrize("encoding", ["raw", "gzip"])
def test_a_nrrd_header_declaring_more_than_its_data_is_refused_before_reading(tmp_path, encoding):
    import nrrd

    path = tmp_path / "liar.nrrd"
    nrrd.write(str(path), np.zeros((4, 4, 4), np.float32), {"encoding": encoding})
    text = path.read_bytes()
    path.write_bytes(text.replace(b"sizes: 4 4 4", b"sizes: 4000 4000 4000"))  # 256 GB declared
    start = time.process_time()
    with pytest.raises(FileFormatError, match="declares 4000 x 4000 x 4000 voxels") as exc:
        clwave.load(path)
    assert time.process_time() - start < 1.0
    # the bytes it holds: a gzip stream's uncompressed length (its header is outside it), else after the header
    held = "its gzip stream holds 256 bytes;" if encoding == "gzip" else "the file holds 256 bytes after its"
    assert held in str(exc.value) and ("byte header" in str(exc.value)) == (encoding == "raw")


def test_a_npy_header_declaring_more_than_its_data_is_refused_before_mapping(tmp_path):
    np.save(tmp_path / "v.npy", np.zeros((4, 4, 4), np.float32))
    path = tmp_path / "liar.npy"  # once "mmap length is greater than file size"
    path.write_bytes((tmp_path / "v.npy").read_bytes().replace(b"(4, 4, 4), }", b"(4000,4,4),}"))
    with pytest.raises(FileFormatError, match=r"declares 4000 x 4 x 4 voxels \(256,000 bytes\) but the file holds "
                                              r"256 bytes after its 128-byte header"):
        clwave.load(path)


def test_a_volume_too_big_for_any_chunking_names_its_bytes(tmp_path, capsys):
    import h5py

    with h5py.File(tmp_path / "huge.h5", "w") as fh:  # 4 PB declared, nothing written
        fh.create_dataset("v", shape=(100000,) * 3, dtype="f4", chunks=(64, 64, 64))
    with pytest.raises(InputError, match=r"100000 x 100000 x 100000 volume \(4,000,000,000,000,000 bytes as "
                                         r"float32\), too big for this machine") as excinfo:
        clwave.load(tmp_path / "huge.h5")
    assert "chunk edge" not in str(excinfo.value)
    from clwave.cli import main
    assert main(["compress", str(tmp_path / "huge.h5"), "-o", str(tmp_path / "o.clw")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "too big for this machine" in err
    # an edge of few chunks, each too big for memory: weighed before a chunk is read
    with pytest.raises(clwave.HostMemoryError, match=r"a 20000 x 20000 x 20000 chunk of .* as float32 needs about "
                                                     r".*; give a smaller chunk edge"):
        clwave.load(tmp_path / "huge.h5", chunks=20000)


def test_ctrl_c_stops_a_long_splat_within_a_second(tmp_path):
    """A 1000^2 splat of every coefficient of 32^3 at single resolution (``--coarse 0``: an 8-bit PNG's default coarse
    framebuffers would end it in a second) accumulates for many seconds on 2 cores; its launches
    are bounded (docs/splatting.md §6), so the command line takes Ctrl-C within a second of the signal, sent while a
    launch of the accumulation runs: one line, code 130, nothing written."""
    script = f"""
import sys
from clwave import cli
from clwave.splat import stages
{LAUNCHED.format(module="stages", bands="bands")}
accumulating = stages.Stages.accumulating
def announced(self, *args):
    stages.bands = launched  # the accumulation's bands, not those placing the splats
    return accumulating(self, *args)
stages.Stages.accumulating = announced
sys.exit(cli.main(["render", "phantom:hydrogen:32", "--levels", "2", "--keep", "1", "--size", "1000",
                   "--coarse", "0", "-o", {str(tmp_path / 'out.png')!r}]))
"""
    seconds, code, _, err = interrupted(script, b"clwave: interrupted")
    assert seconds < 1.0 and code == 130 and err.decode().strip() == "clwave: interrupted"
    assert not list(tmp_path.iterdir())


#: a ``launched`` wrapper of ``{module}.{bands}`` (kernels.bands, in_bands or in_row_bands as a module imported it) that
#: prints "launched" as it launches each band from half a second into its first call: bands grown to their pace
LAUNCHED = """
import time
_bands, _begun = {module}.{bands}, []
def launched(queue, launch, *args, **kwargs):
    _begun.append(_begun[0] if _begun else time.perf_counter())
    def announced(*band):
        launch(*band)
        if time.perf_counter() - _begun[0] > 0.5:
            print("launched", flush=True)
    return _bands(queue, announced, *args, **kwargs)
"""


def sigint_default():
    """A child's SIGINT as a terminal's Ctrl-C finds it: a suite run as a background job (``pytest &`` in a script)
    hands its children SIGINT ignored, and Python then installs no KeyboardInterrupt handler."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def interrupted(script: str, stopped: bytes) -> tuple:
    """Run ``script`` in a Python process of its own, send SIGINT as soon as it prints "launched" (a launch of its
    long work running, LAUNCHED), and return (seconds from the signal to the line holding ``stopped`` on its stderr:
    the work given up, not counting the interpreter's own exit, which load stretches; exit code, stdout, stderr).
    Its stderr is read on a thread of its own from the start, so that neither pipe can fill and block the other.
    SIGINT is given its default disposition first (:func:`sigint_default`)."""
    with subprocess.Popen([sys.executable, "-c", script], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)), preexec_fn=sigint_default) as proc:
        err, seen = [], threading.Event()

        def read_stderr():
            for line in proc.stderr:
                err.append(line)
                if stopped in line:
                    seen.set()  # time.perf_counter() below: the moment this thread sees it

        reader = threading.Thread(target=read_stderr, daemon=True)
        reader.start()
        for line in proc.stdout:
            if line.startswith(b"launched"):
                break
        else:
            reader.join(timeout=60)
            pytest.fail(f"the work ended before it was interrupted: {b''.join(err).decode()[-2000:]}")
        start = time.perf_counter()
        proc.send_signal(signal.SIGINT)
        seen.wait(timeout=60)
        seconds = time.perf_counter() - start
        proc.wait(timeout=60)
        reader.join(timeout=60)
        return seconds, proc.returncode, proc.stdout.read(), b"".join(err)


def test_a_disk_filling_while_a_clw_is_written_is_one_line_and_leaves_nothing(tmp_path):
    """The disk fills at every stage of the write: the first chunks, the middle, the last byte of the close
    (HDF5 writes metadata then). One line, exit 2, nothing left; never the SIGSEGV of a file HDF5 could not
    close (docs/chunked.md §4)."""
    argv = ["compress", "phantom:hydrogen:32", "--levels", "2", "--keep", "0.5"]
    from clwave.cli import main

    assert main(argv + ["-o", str(tmp_path / "whole.clw")]) == 0
    size = (tmp_path / "whole.clw").stat().st_size
    for limit in (1000, size // 2, size - 1):
        folder = tmp_path / f"full{limit}"
        folder.mkdir()
        script = f"""
import errno, io, sys
from clwave import cli

class Full(io.FileIO):  # a disk with {limit} bytes free
    def write(self, data):
        if self.tell() + len(memoryview(data).cast("B")) > {limit}:
            raise OSError(errno.ENOSPC, "No space left on device")
        return super().write(data)

io.FileIO = Full
sys.exit(cli.main({argv + ["-o", str(folder / "out.clw")]!r}))
"""
        proc = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=120,
                              env=dict(os.environ, PYTHONPATH=str(ROOT)))
        assert proc.returncode == 2, (limit, proc.returncode, proc.stderr[-2000:])
        assert proc.stderr.splitlines() == [f"clwave: error: cannot write {folder / 'out.clw'}: No space left on "
                                            "device; check the folder's permissions and free space"], proc.stderr
        assert not list(folder.iterdir())


@pytest.mark.parametrize("extra, needle", [
    (["--raw", "{d}/missing/raw.npy"], "the folder of --raw {d}/missing/raw.npy does not exist"),
    (["--raw", "{d}/raw.txt"], "--raw {d}/raw.txt must end in .npy"),
    (["--raw", "{d}/x.png"], "--raw {d}/x.png must end in .npy"),
    (["--stats", "{d}/s.npy"], "--stats {d}/s.npy must end in .json"),
    (["--raw", "{d}/r.json"], "--raw {d}/r.json must end in .npy"),
    (["--raw", "{d}/r.npy", "--stats", "{d}/r.npy"], "--stats {d}/r.npy must end in .json"),
    (["--raw", "{d}/sub"], "--raw {d}/sub must end in .npy"),
    (["--raw", "{d}/sub.npy"], "--raw {d}/sub.npy is a folder; name a file"),
    (["--raw", "{d}/old.npy"], "{d}/old.npy exists; pass --force"),
])
def test_every_render_output_is_checked_before_any_work(tmp_path, capsys, monkeypatch, extra, needle):
    from clwave.cli import main, render

    (tmp_path / "sub").mkdir()
    (tmp_path / "sub.npy").mkdir()
    (tmp_path / "old.npy").write_bytes(b"precious")
    monkeypatch.setattr(render, "build_model", lambda *a, **k: pytest.fail("work started"))
    before = sorted(p.name for p in tmp_path.iterdir())
    code = main(["render", "phantom:hydrogen:16", "--levels", "1", "--size", "8", "-o", str(tmp_path / "x.png")]
                + [e.format(d=tmp_path) for e in extra])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith(f"clwave: error: {needle.format(d=tmp_path)}") and err.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == before and (tmp_path / "old.npy").read_bytes() == b"precious"


def test_two_outputs_naming_one_file_are_refused_before_any_work(tmp_path, capsys, monkeypatch):
    """--raw equal to -o, and a --stats name that is a (dangling) link to the -o file: the second write would
    find the first's file, after the work and the first write."""
    from clwave.cli import main, render

    monkeypatch.setattr(render, "build_model", lambda *a, **k: pytest.fail("work started"))
    png = tmp_path / "x.png"
    (tmp_path / "s.json").symlink_to(png)
    for extra, needle in ((["--raw", str(png)], f"--raw {png} must end in .npy"),
                          (["--stats", str(tmp_path / "s.json")], f"-o and --stats both name {tmp_path / 's.json'}")):
        assert main(["render", "phantom:hydrogen:16", "-o", str(png)] + extra) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"clwave: error: {needle}") and err.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.json"]


def test_progressive_into_an_existing_file_without_a_suffix_is_one_line(tmp_path, capsys):
    from clwave.cli import main

    (tmp_path / "frames").write_bytes(b"precious")
    assert main(["progressive", "phantom:hydrogen:16", "--levels", "1", "-o", str(tmp_path / "frames")]) == 2
    assert capsys.readouterr().err == (f"clwave: error: -o {tmp_path / 'frames'} is a file; name a folder for the "
                                       "PNG frames, or a .gif\n")
    assert (tmp_path / "frames").read_bytes() == b"precious"


def test_a_buffer_over_the_limit_names_the_true_fix():
    # known-gaps §15: a larger device memory where only the user's cap holds the buffer back, else the other fix
    from types import SimpleNamespace

    from clwave.device.memory import DeviceBudget, check_buffer

    cc = SimpleNamespace(info=SimpleNamespace(max_alloc=64 << 20, global_mem=256 << 20, name="Dev"))
    capped = DeviceBudget(2 << 20, 2 << 20, 2 << 20)
    check_buffer(cc, 2 << 20, "x", "fix", capped)  # at the limit: no refusal
    with pytest.raises(clwave.DeviceMemoryError) as err:
        check_buffer(cc, 3 << 20, "a 9x9 image", "render a smaller image", capped)
    assert str(err.value) == ("a 9x9 image needs 3 MiB in one device buffer, more than device_memory=2 MiB allows; "
                              "give device_memory= at least 3 MiB, or render a smaller image")
    assert err.value.cli_message() == ("a 9x9 image needs 3 MiB in one device buffer, more than --device-memory "
                                       "2MiB allows; give --device-memory 3MiB or more, or render a smaller image")
    with pytest.raises(clwave.DeviceMemoryError, match="device_memory= at least 6 MiB, or F$"):  # half the budget
        check_buffer(cc, 3 << 20, "w", "F", DeviceBudget(5 << 20, 5 << 20, 5 << 20), share=0.5)
    for budget in (capped, None, DeviceBudget(256 << 20, 64 << 20)):  # beyond the device's own limit: no cap helps
        with pytest.raises(clwave.DeviceMemoryError) as err:
            check_buffer(cc, 65 << 20, "a 9x9 image", "render a smaller image", budget)
        assert str(err.value) == err.value.cli_message() == (
            "a 9x9 image needs 65 MiB in one device buffer, but Dev allows 64 MiB whatever the device memory given; "
            "render a smaller image")


def test_an_image_beyond_the_hosts_memory_is_refused_before_its_buffers(tmp_path, capsys, monkeypatch):
    """trial24 row 15: --size 20000 ran for minutes. An image whose memory (its host copies, HOST_PIXEL_BYTES a pixel,
    and on a CPU device its device buffer, the host's memory too) is beyond what the host has available (a tiny fake
    figure here) is refused before a buffer is made, in one line naming the size, the bytes and the fix: exit 2 on
    the command line, a MemoryError in the API (Camera(size=), splat, raytrace, progressive)."""
    from math import isqrt

    from clwave.cli import main
    from clwave.device import memory

    wv = clwave.WaveletVolume.from_volume(clwave.TransferFunction.preset("hydrogen").classify(
        clwave.phantom("hydrogen", n=12)), levels=1)
    splatter, tracer = clwave.SplatRenderer(wv), clwave.RayTracer(wv)  # planned with the memory there is
    camera = clwave.Camera(size=200)
    monkeypatch.setattr(memory, "available_bytes", lambda: 1 << 20)  # 1 MiB
    with pytest.raises(clwave.HostMemoryError) as err:
        clwave.Camera(size=300)  # its host copies alone: 300^2 x 20 bytes
    assert str(err.value) == ("a 300x300 image needs about 1.8 MiB, and this machine has 1 MiB available; give a "
                              "smaller size= (at most 228x228 here)")
    # on a CPU device, in the host's memory: the least the splatter needs for the view before its footprints, its
    # framebuffer, 13 x 13 tiles' ranges and 1024 coefficients of 64 bytes over 1 - 1/4 - 1/32 of its budget
    least = (16 * 200 ** 2 + 8 * 13 ** 2 + 64 * min(1024, splatter.count)) / (1 - 1 / 4 - 1 / 32)
    device = int(least) + 1 if splatter.cc.info.kind == "CPU" else 0
    with pytest.raises(clwave.HostMemoryError, match=r"^the framebuffer of a 200x200 image needs about "
                       rf"{memory.format_size(20 * 200 ** 2 + device)}, and this machine has 1 MiB available; "
                       r"render a smaller image \(at most \d+x\d+ here\)$"):
        clwave.splat(wv, camera, renderer=splatter)
    with pytest.raises(clwave.HostMemoryError, match=r"^a 200x200 image needs about .* 1 MiB available; render a "
                                                     r"smaller image \(at most \d+x\d+ here\)$"):
        tracer.render(camera)
    for render in (clwave.splat, clwave.raytrace, lambda w, c: list(clwave.progressive(w, c, steps=2))):
        with pytest.raises(MemoryError) as err:  # the renderer planned within the 1 MiB, or the image refused
            render(wv, camera)
        assert "\n" not in str(err.value)
    (tmp_path / "v.npy").write_bytes(b"never read")
    for method, pixel in (("splat", 16), ("raytrace", 32)):  # device/memory.py: FRAMEBUFFER_, TRACED_PIXEL_BYTES
        assert main(["render", str(tmp_path / "v.npy"), "--size", "400", "--method", method, "-o",
                     str(tmp_path / "a.png")]) == 2
        per = 20 + (pixel if splatter.cc.info.kind == "CPU" else 0)  # the device buffer in the host's memory
        most = isqrt((1 << 20) // per)
        assert capsys.readouterr().err.splitlines() == [
            f"clwave: error: a 400x400 image needs about {memory.format_size(400 ** 2 * per)}, and this "
            f"machine has 1 MiB available; give a smaller --size (at most {most}x{most} here)"]
    assert not (tmp_path / "a.png").exists()


def test_an_image_over_the_device_memory_cap_names_a_larger_cap(tmp_path, capsys):
    from clwave.cli import main

    out = tmp_path / "x.png"
    argv = ["render", "phantom:hydrogen:8", "--levels", "1", "--method", "raytrace", "--xray", "--size", "300"]
    assert main([*argv, "--device-memory", "2M", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and not out.exists()
    assert "more than --device-memory 2MiB allows; give --device-memory 2.8MiB or more" in err


def test_an_array_beyond_float32_is_named_so_not_as_nan():
    """Finite float64 values that float32 cannot hold turn into inf when converted: the refusal says which (no
    RuntimeWarning of the cast first)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(InputError, match="non-finite voxel value.*or beyond float32's range of \\+-3.4e38"):
            clwave.Volume(np.full((4, 4, 4), 1e300))
