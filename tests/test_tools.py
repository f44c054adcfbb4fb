"""tools/figures.py and tools/compare_peers.py end to end on a 32³ volume at 64²."""

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import nibabel
import numpy as np
import pytest

import clwave

ROOT = Path(__file__).resolve().parents[1]
HAVE_VTK = importlib.util.find_spec("vtk") is not None
# a real (tiny) MRI that nibabel, a dependency, ships: 33 x 41 x 25 voxels of 2 mm
SCAN = Path(nibabel.__file__).parent / "tests" / "data" / "anatomical.nii"

pytestmark = pytest.mark.slow


def run_tool(name, *args):
    proc = subprocess.run([sys.executable, str(ROOT / "tools" / name), *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-4000:]
    return proc.stdout


def test_figures_end_to_end(tmp_path):
    ct = tmp_path / "ct.nii.gz"  # a CT in Hounsfield units: air -1000 outside, bone up to +1000
    nibabel.save(nibabel.Nifti1Image(clwave.phantom("shepp-logan", 32).data.T * 2000.0 - 1000.0, np.eye(4)), ct)
    out = run_tool("figures.py", "--out", tmp_path, "--size", 32, "--image", 64, "--scan", SCAN, "--scan-step", 1,
                   "--ct", ct, "--ct-step", 2, "--raytrace-image", 32)
    names = {p.name for p in tmp_path.iterdir()}
    assert {"table1.md", "fig07_footprints.png"} <= names
    for fig in ("fig10", "fig11", "fig12", "fig14", "fig15", "fig16", "fig17"):
        assert {f"{fig}_hydrogen.png", f"{fig}_scan.png"} <= names
    assert "fig14_ct.png" in names  # Fig. 14's CT
    # Table I: our sample counts equal the paper's, cell by cell ("ours / paper"); the quintic column, which the
    # paper lacks, equals eq. 36 with the psi support 11 worked by hand
    rows = [line for line in (tmp_path / "table1.md").read_text().splitlines() if line.startswith("| ") and
            line[2].isdigit()]
    assert len(rows) == 4
    for m, row in enumerate(rows):
        cells = row.strip("|").split("|")[1:]
        assert len(cells) == 4
        for cell in cells[:3]:
            ours, paper = cell.split("/")
            assert int(ours) == int(paper)
        ours, paper = cells[3].split("/")
        assert paper.strip() == "–" and int(ours) == [86, 171, 341, 681][m]
    assert "figures written to" in out


def test_compare_peers_end_to_end(tmp_path):
    run_tool("compare_peers.py", "--phantom", "hydrogen", "--size", 32, "--image", 64, "--views", 2,
             "--keep", 0.05, 1.0, "--progressive-keep", 0.5, "--steps", 3, "--raytrace-keep", 1.0, "--out", tmp_path,
             "--vtk-sweep", 2, 1, "--vtk-resample", 1, 2, "--sweep-tolerance", 0.1, 0.01, "--sweep-keep", 1,
             "--sweep-rounds", 1)
    report = json.loads((tmp_path / "comparison.json").read_text())
    (case,) = report["cases"]
    rows = {r["method"]: r for r in case["rows"]}
    assert case["truth_accuracy"] < 1e-4  # Gauss-Legendre quadrature against twice the segments
    # every line-integral method is timed and close to the analytic truth at full resolution
    # ray tracing in X-ray mode integrates the same spline as splatting, within 1e-3 per value
    for label, bound in (("clwave splat 1, renderer reused", 0.06), ("clwave raytrace 1 (X-ray, tol 0.001)", 0.06),
                         ("NumPy/SciPy map_coordinates", 0.03), ("Fourier volume rendering", 0.005)):
        assert rows[label]["error"] < bound, (label, rows[label]["error"])
        assert rows[label]["median"] > 0 and rows[label]["peak_rss_mib"] > 0
        memory = rows[label]["memory_mib"]
        assert memory["baseline"] > 0 and memory["model"] >= 0 and memory["views"] >= 0
    # the one-shot call renders what the reused renderer renders
    assert rows["clwave splat 0.05, one-shot clwave.splat"]["error"] == pytest.approx(
        rows["clwave splat 0.05, renderer reused"]["error"], rel=1e-4)
    progressive = [r for r in case["rows"] if r["method"].startswith("clwave progressive")]
    assert len(progressive) == 3 and [r["frame"] for r in progressive] == [0, 1, 2]
    assert progressive[-1]["error"] < progressive[0]["error"]
    assert progressive[-1]["kept"] == pytest.approx(0.5, abs=1e-3)
    # shaded ray tracing against the float64 reference of the same classified model: converges with the model
    shaded = {r["method"]: r for r in case["rows"] if r.get("kind") == "shaded" and "error" in r}
    assert shaded["clwave raytrace 1 (shaded, tol 0.01)"]["error"] < 0.05
    assert shaded["clwave raytrace 1 (shaded, tol 0.01)"]["error"] < shaded["clwave raytrace 0.05 (shaded, tol 0.01)"][
        "error"]
    # post-classified (the scalar model through the preset at render time) against its own float64 reference: the
    # pre-classified rows' bound, as both now spend the tolerance's shading share at the segment's midpoint
    # (docs/raytracing.md §5, §10; the per-value bound itself: tests/test_classify.py)
    post = shaded["clwave raytrace 1 (post-classified, shaded, tol 0.01)"]["error"]
    assert post < 0.05 and post < shaded["clwave raytrace 0.05 (post-classified, shaded, tol 0.01)"]["error"]
    table = (tmp_path / "comparison.md").read_text()
    assert "| hydrogen | 32³ | Fourier volume rendering |" in table
    assert report["headline"] and "clwave / FVR" in report["headline"][0]
    if not HAVE_VTK:
        assert "skipped" in rows["VTK additive"] and "skipped" in rows["sweep"]
        pytest.skip("vtk is not installed (pip install .[peers]): the VTK rows were skipped")
    for label in ("VTK additive", "VTK composite (shaded, hydrogen)"):
        row = rows[label]
        assert "skipped" not in row and row["median"] > 0 and len(row["extra"]["readback"]) == 2
        assert row["extra"]["window"] == "vtkEGLRenderWindow"
    assert "error" not in rows["VTK additive"]
    # VTK's composite with clwave's transfer function, opacity units and Phong light: close to clwave's post-classified
    # image
    assert rows["VTK composite (shaded, hydrogen)"]["error"] < 0.15
    assert (tmp_path / "error_vs_time.png").exists()
    # the sweep at equal error (one process): clwave converges with its tolerance; VTK at its defaults renders what the
    # VTK composite row rendered; the cubic B-spline resampled twice finer brings VTK closer to the reference
    sweep = {r["method"]: r for r in case["rows"] if "sweep" in r}
    assert len(sweep) == 2 + 2 * 2 and all(r["median"] > 0 for r in sweep.values())
    clwave_rows = [sweep[f"sweep: clwave raytrace 1 (post-classified, tol {t})"] for t in ("0.1", "0.01")]
    assert clwave_rows[1]["error"] < clwave_rows[0]["error"]
    assert clwave_rows[1]["error"] == pytest.approx(post, rel=1e-3)  # the same render as the post row
    vtk = lambda d, f: sweep[f"sweep: VTK composite, distance {d}, linear, volume x{f}, window 1"]  # noqa: E731
    assert vtk(1, 1)["error"] == pytest.approx(rows["VTK composite (shaded, hydrogen)"]["error"], rel=1e-6)
    assert vtk(1, 2)["error"] < vtk(1, 1)["error"]
    assert 0 < case["eight_bit_error"]["1"] < vtk(1, 1)["error"]  # its 8-bit output: part of its error
    lines = [t for t in report["headline"] if "at equal error" in t]
    assert len(lines) == 4 and lines[-2].startswith("hydrogen 32³ at 64², at equal error: VTK distance 1 linear x1")


def test_equal_error_measured_interpolated_or_not_reached():
    """peers_report.at_error on a made-up sweep: the fastest setting at or under the error; a crossing between two
    neighbouring settings interpolated in log time against log error (exact for a power law); none past the floor."""
    sys.path.insert(0, str(ROOT / "tools"))
    from peers_report import at_error, equal_error

    def row(side, swept, seconds, error):
        setting = dict(side="clwave", tolerance=swept) if side == "clwave" else dict(
            side="vtk", distance=swept, interpolation="linear", resample=1, window=1.0)
        return dict(sweep=setting, median=seconds, error=error)

    # VTK: error = 0.02 * d, seconds = 0.1 / d (error * seconds = 2e-3), floor 0.005 at d = 0.25
    vtk = [row("vtk", d, 0.1 / d, 0.02 * d) for d in (2.0, 1.0, 0.5, 0.25)]
    found = at_error(vtk, 0.01)
    assert found["how"] == "measured" and found["seconds"] == pytest.approx(0.2)
    found = at_error(vtk, 0.0141)
    assert found["how"] == "interpolated" and found["seconds"] == pytest.approx(2e-3 / 0.0141)
    assert found["row"]["sweep"]["distance"] == 0.5 and found["between"]["sweep"]["distance"] == 1.0
    found = at_error(vtk, 0.001)
    assert found["seconds"] is None and found["row"]["error"] == pytest.approx(0.005)
    clwave = [row("clwave", 1e-2, 1.0, 0.006), row("clwave", 1e-3, 2.0, 0.0006)]
    pairs = equal_error(clwave + vtk)
    assert [p["how"] for p in pairs] == ["interpolated", "not reached", "measured", "interpolated"]
    assert pairs[0]["seconds"] == pytest.approx(2e-3 / 0.006)              # VTK at clwave's 0.6 %
    assert pairs[2]["given"] is vtk[1] and pairs[2]["seconds"] == 1.0      # clwave at VTK's defaults' 2 %
    assert pairs[3]["given"] is vtk[3] and 1.0 < pairs[3]["seconds"] < 2.0  # clwave at VTK's floor, 0.5 %


def test_vtk_finer_volume_is_the_cubic_model():
    """The sweep's finer volume for VTK (vtkImageReslice, vtkImageBSplineInterpolator, the voxels as coefficients
    over 2 voxels of zeros) samples clwave's approximating cubic model (docs/coordinates.md §1), edges included."""
    pytest.importorskip("vtk")
    sys.path.insert(0, str(ROOT / "tools"))
    from peers_vtk import _image
    from vtkmodules.util.numpy_support import vtk_to_numpy

    vol = clwave.phantom("marschner-lobb", 12)  # not zero on its faces
    image = _image(vol, 2)
    nx, ny, nz = image.GetDimensions()
    assert (nx, ny, nz) == (2 * (12 + 3) + 1,) * 3
    values = vtk_to_numpy(image.GetPointData().GetScalars()).reshape(nz, ny, nx)
    index = np.random.default_rng(0).integers(0, nx, (300, 3))  # (x, y, z)
    points = np.array(image.GetOrigin()) + index * np.array(image.GetSpacing())
    model = clwave.WaveletVolume.from_volume(vol, wavelet="cubic", levels=1).evaluate(points)[:, 0]
    np.testing.assert_allclose(values[index[:, 2], index[:, 1], index[:, 0]], model, atol=1e-6)


def test_the_view_bench_drags_on_small_images():
    """tools/bench.py view's drag (bench_view.drag_path) on the viewer's page in headless chromium: pressed where the
    page's status line is not (at 48² it covered the image's centre, where the drag once pressed) and staying in the
    image, it orbits by 0.4° a pixel (static/controls.js) as far as it moved; 240 x 60 pixels in 60 moves at 512²."""
    sys.path.insert(0, str(ROOT / "tools"))
    import browser
    from bench_view import _view_drag, drag_path

    if browser.executables() is None:
        pytest.fail(browser.SETUP)
    assert drag_path(512) == ((-120, -192), (240, 60), 60)
    for size in range(32, 1025):
        (x, y), (dx, dy), moves = drag_path(size)
        x, y = x + size // 2, y + size // 2  # from the image's top left corner
        assert 0 < x < x + dx < size and 0 < y <= y + dy < size - 25 and moves >= 15  # the status line: 25 pixels
    with pytest.raises(SystemExit, match="at least 32 pixels"):
        drag_path(31)
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", 16), levels=1).threshold(keep=0.2)
    with browser.chromium() as driver:
        for size in (32, 48):
            with clwave.view(wv, size=size) as viewer:
                browser.open_viewer(driver, viewer.url)
                browser.wait_final(driver)
                before = driver.execute_script("return [window.clwave.state.azimuth, window.clwave.state.elevation]")
                _, (dx, dy), _ = drag = drag_path(size)
                _view_drag(browser, driver, drag)
                browser.release(driver)
                final = browser.wait_final(driver)
                assert driver.execute_script("return window.clwave.stats.released") is not None
                assert np.isclose(final["azimuth"], (before[0] - 0.4 * dx) % 360)
                assert np.isclose(final["elevation"], before[1] + 0.4 * dy)


def test_staged_estimate_reports_each_frames_terms(tmp_path):
    """tools/staged_estimate.py --file: per coarse frame its ratios (estimate over error) and the file's two terms,
    the staged tracer's own."""
    path = tmp_path / "h.clw"
    rgba = clwave.TransferFunction.preset("hydrogen").classify(clwave.phantom("hydrogen", 32))
    clwave.WaveletVolume.from_volume(rgba, wavelet="cubic", levels=3).threshold(keep=0.05).save(path)
    run_tool("staged_estimate.py", "--file", path, "--size", 64, "--json", tmp_path / "out.json")
    rows = json.loads((tmp_path / "out.json").read_text())["rows"]
    tracer = clwave.RayTracer.open(path)
    assert [r["mode"] for r in rows] == ["shaded", "shaded", "xray", "xray"]
    for r in rows:
        assert (r["missing"], r["outside"]) == (tracer.missing, tracer.outside) and tracer.outside > 0
        assert r["rms_ratio"] == r["rms_estimate"] / r["rms_error"] > 0
    assert rows[0]["reduction"] == 2 * rows[1]["reduction"]  # both coarse frames, the smaller first


def test_estimate_sweep_splits_its_frames_by_seed(tmp_path):
    """tools/estimate_sweep.py on a tuning and a held-out seed (one-level X-ray cases): every frame before the last,
    direct and staged, its ratios the estimate over the measured error, summed per half and kind; seed 24, whose
    final image sees nothing (a post-classified `ct-bone` case), left out: no relative error to estimate."""
    printed = run_tool("estimate_sweep.py", "--seeds", "23,24,42", "--json", tmp_path / "out.json")
    out = json.loads((tmp_path / "out.json").read_text())
    rows, summary = out["rows"], out["summary"]
    assert " 24 the final image sees nothing: left out" in printed
    assert {r["seed"] for r in rows} == {23, 42} and {r["kind"] for r in rows} == {"direct", "staged 1"}
    for r in rows:
        for n in ("rms", "max"):
            assert r[f"{n}_ratio"] == r[f"{n}_estimate"] / r[f"{n}_error"] > 0
    for half, parity in (("tuning", 0), ("held-out", 1)):
        for kind in ("direct", "staged 1"):
            mine = [r for r in rows if r["seed"] % 2 == parity and r["kind"] == kind]
            assert summary[f"{half} {kind}"]["frames"] == len(mine) > 0
            assert summary[f"{half} {kind}"]["both_within_1_4"] == sum(
                all(1 <= r[f"{n}_ratio"] <= 4 for n in ("rms", "max")) for r in mine)


def test_noise_table_rows(tmp_path):
    """tools/noise_table.py on a noisy blob: a row per wavelet, the noise rule's error below keep=0.05's for linear."""
    z, y, x = np.mgrid[:32, :32, :32] / 32
    clean = (10 * np.exp(-((x - .5) ** 2 + (y - .5) ** 2 + (z - .5) ** 2) / 0.04)).astype(np.float32)
    np.save(tmp_path / "clean.npy", clean)
    np.save(tmp_path / "noisy.npy", clean + np.random.default_rng(1).normal(0, 1, clean.shape).astype(np.float32))
    out = run_tool("noise_table.py", tmp_path / "noisy.npy", tmp_path / "clean.npy", "--sigma", 1, "--levels", 2)
    rows = {line.split(" | ")[0].strip("| "): line for line in out.splitlines()[2:]}
    assert set(rows) == {"haar", "linear", "quadratic", "cubic"}
    linear = [float(cell.split(" σ")[0]) for cell in rows["linear"].split(" | ")[1:]]
    assert linear[1] < linear[0]
