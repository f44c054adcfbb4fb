"""tools/gpu_check.sh, small, on PoCL (--device cpu): it stays ready for the day a GPU is lent."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def check(tmp_path, *options) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", "tools/gpu_check.sh", "--device", "cpu", "--sizes", "16", "--image", "48", *options],
                          cwd=ROOT, capture_output=True, text=True, timeout=600,
                          env=dict(os.environ, CLWAVE_PYTHON=sys.executable))


def test_gpu_check_runs_the_tests_times_the_views_and_compares_them_with_reference_images(tmp_path):
    ref, first, second = tmp_path / "ref", tmp_path / "first", tmp_path / "second"
    run = check(tmp_path, "--tests", "tests/test_device.py", "--out", str(first), "--save-reference", str(ref))
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    assert "passed" in (first / "tests.txt").read_text() and "pthread" in (first / "devices.txt").read_text()
    report = json.loads((first / "gpu_check.json").read_text())
    assert report["device"]["type"] == "CPU" and report["device"]["is_pocl"]
    assert set(report["cases"]) == {"raytrace 16", "splat 16"}
    assert all(len(c["render_seconds"]) == 2 and c["setup_seconds"] > 0 for c in report["cases"].values())
    assert sorted(p.name for p in ref.iterdir()) == [f"{m}_16_{i}.npy" for m in ("raytrace", "splat") for i in (0, 1)]

    image = np.load(ref / "splat_16_1.npy")  # a reference 1e-3 of its maximum off: told, and the exit says so
    image.flat[np.argmax(image)] *= 1.001
    np.save(ref / "splat_16_1.npy", image)
    run = check(tmp_path, "--no-tests", "--out", str(second), "--reference", str(ref))
    assert run.returncode == 1 and "FAILED" in run.stdout, run.stdout[-3000:] + run.stderr[-3000:]
    cases = json.loads((second / "gpu_check.json").read_text())["cases"]
    assert cases["raytrace 16"]["relative_max_errors"] == [0.0, 0.0] and cases["raytrace 16"]["within_bound"]
    assert cases["splat 16"]["relative_max_errors"][0] == 0.0 and not cases["splat 16"]["within_bound"]
    assert abs(cases["splat 16"]["relative_max_errors"][1] - 1e-3 / 1.001) < 1e-6
