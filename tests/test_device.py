"""Device choice (no hardware needed) and the kernel build path (on the real device)."""

import json
from types import SimpleNamespace

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
import pytest

from clwave.device import kernels, programs
from clwave.device.context import ComputeContext, DeviceInfo, select_device
from clwave.errors import DeviceNotFoundError, InputError, KernelBuildError

FAKE = [
    DeviceInfo(0, 0, "Portable Computing Language", "pthread-cpu", "CPU", 8 << 30, 2 << 30, 1 << 20, 2, "OpenCL 3.0"),
    DeviceInfo(1, 0, "NVIDIA CUDA", "NVIDIA H100", "GPU", 80 << 30, 20 << 30, 48 << 10, 132, "OpenCL 3.0"),
    DeviceInfo(1, 1, "NVIDIA CUDA", "NVIDIA T4", "GPU", 16 << 30, 4 << 30, 48 << 10, 40, "OpenCL 3.0"),
]


@pytest.fixture(autouse=True)
def clean_env(monkeypatch):
    monkeypatch.delenv("CLWAVE_DEVICE", raising=False)
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)


@pytest.mark.parametrize("request_, expected", [
    ("auto", "1:0"), (None, "1:0"), ("gpu", "1:0"), ("cpu", "0:0"), ("1:1", "1:1"), ("1", "1:0"),
    ("0:0", "0:0"), ("t4", "1:1"), ("portable", "0:0"), ("NVIDIA", "1:0"), ("pocl", "0:0"), ("PoCL", "0:0"),
])
def test_device_requests(request_, expected):
    assert select_device(request_, FAKE).id == expected


def test_environment_is_honoured_and_argument_wins(monkeypatch):
    monkeypatch.setenv("PYOPENCL_CTX", "0:0")
    assert select_device(None, FAKE).id == "0:0"
    monkeypatch.setenv("CLWAVE_DEVICE", "t4")
    assert select_device("auto", FAKE).id == "1:1"
    assert select_device("cpu", FAKE).id == "0:0"


def test_an_int_is_a_platform_index_and_an_empty_request_is_refused():
    """device=1 is "1" (the trial read device=5's "no OpenCL device matches '5'" as ints refused: there is no
    platform 5); "" silently meant auto, and True or 0.0 were looked up as names: each refused in one line."""
    assert select_device(1, FAKE).id == "1:0" and select_device(np.int64(0), FAKE).id == "0:0"
    for bad in ("", "  ", True, 0.0):
        with pytest.raises(InputError, match=f"^device={bad!r} names no device: give 'auto'"):
            select_device(bad, FAKE)
    with pytest.raises(DeviceNotFoundError, match="no OpenCL device matches '5'"):
        select_device(5, FAKE)


@pytest.mark.parametrize("bad", ["2:0", "gpu-that-is-not-there", "0:5"])
def test_unknown_device_is_one_line(bad):
    with pytest.raises(DeviceNotFoundError) as err:
        select_device(bad, FAKE)
    assert "\n" not in str(err.value) and "available" in str(err.value)
    with pytest.raises(DeviceNotFoundError):
        select_device("gpu", FAKE[:1])


def test_context_is_shared_and_describes_its_device(cc):
    assert ComputeContext.get(cc.info.id) is cc
    assert ComputeContext.get(cc) is cc
    device, described = cc.queue.device, cc.describe()  # what the driver says, and what clwave reports
    assert described["device"] == device.name.strip() and described["platform"] == device.platform.name.strip()
    assert (described["global_mem_bytes"], described["max_alloc_bytes"], described["compute_units"]) == \
        (device.global_mem_size, device.max_mem_alloc_size, device.max_compute_units)
    assert described["type"] == ("GPU" if device.type & cl.device_type.GPU else "CPU")


@pytest.mark.parametrize("local", [None, (1,)])
def test_selftest_kernel_matches_numpy(cc, local):
    ks = programs.build(cc, ["device/selftest.cl"])
    assert programs.build(cc, ["device/selftest.cl"]) is ks  # built once
    assert ks.selftest_axpy is ks["selftest_axpy"]  # and each kernel fetched once
    assert any(opt.startswith("-DCLW_SRC_HASH=") for opt in ks.options) and "-I" in ks.options
    rng = np.random.default_rng(0)
    a, b = rng.random(37, dtype=np.float32), rng.random(37, dtype=np.float32)
    d_a, d_b = cla.to_device(cc.queue, a), cla.to_device(cc.queue, b)
    out = cla.empty_like(d_a)
    programs.SELFTEST(ks, cc.queue, (37,), local, alpha=-1.5, a=d_a, b=d_b, out=out)
    assert np.allclose(out.get(), -1.5 * a + b, rtol=1e-6, atol=1e-7)
    assert programs.selftest(cc) >= 0


def test_source_hash_follows_the_sources(tmp_path):
    (tmp_path / "a.cl").write_text("__kernel void k(){}")
    first = programs.source_hash(tmp_path)
    other = tmp_path / "b"
    other.mkdir()
    (other / "a.cl").write_text("__kernel void k(){ }")
    assert programs.source_hash(other) != first


def test_build_failure_is_one_line_with_log(cc, tmp_path, monkeypatch):
    (tmp_path / "broken.cl").write_text("__kernel void broken(__global float *x) { x[0] = y; }\n")
    monkeypatch.setattr(programs, "cl_dir", lambda: tmp_path)
    with pytest.raises(KernelBuildError) as err:
        programs.build(cc, ["broken.cl"])
    assert "\n" not in str(err.value) and "broken.cl" in str(err.value)
    assert "y" in err.value.log


def test_cl_sources_ship_with_the_package():
    folder = programs.cl_dir()
    assert (folder / "common" / "clw_common.h").is_file() and (folder / "device" / "selftest.cl").is_file()
    import tomllib
    from pathlib import Path
    project = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())
    assert project["tool"]["hatch"]["build"]["targets"]["wheel"]["force-include"]["cl"] == "clwave/cl"
    assert cl.get_platforms()  # the loader finds a platform


def test_a_second_renderer_builds_no_program(cc, monkeypatch):
    """Renderers on one context share its programs, pyopencl's generated kernels (scan, reduction,
    element-wise) included: a second splatting renderer and ray tracer build nothing."""
    import clwave

    vol = clwave.phantom("hydrogen", n=16)
    tf = clwave.TransferFunction.preset("hydrogen")
    wv = clwave.WaveletVolume.from_volume(tf.classify(vol), levels=2).threshold(keep=0.2)
    cam = clwave.Camera(azimuth=30, elevation=20, size=16)
    first = (clwave.SplatRenderer(wv, device=cc).render(cam).image,
             clwave.RayTracer(wv, device=cc).render(cam).image)
    builds = []
    build = cl.Program.build
    monkeypatch.setattr(cl.Program, "build", lambda self, *a, **k: builds.append(self) or build(self, *a, **k))
    again = (clwave.SplatRenderer(wv, device=cc).render(cam).image,
             clwave.RayTracer(wv, device=cc).render(cam).image)
    assert builds == []
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a, b)


def test_build_log_has_a_line_a_program_built(cc, tmp_path, monkeypatch):
    """``CLW_BUILD_LOG`` (docs/benchmarks.md §22): one JSON line for each program built, none for one reused."""
    log = tmp_path / "builds.jsonl"
    monkeypatch.setenv("CLW_BUILD_LOG", str(log))
    for _ in range(2):
        programs.build(cc, ["device/selftest.cl"], dict(CLW_LOGGED=1))
    (line,) = [json.loads(text) for text in log.read_text().splitlines()]
    assert line["files"] == ["device/selftest.cl"] and ["CLW_LOGGED", 1] in line["defines"]
    assert line["options"] == [] and line["seconds"] >= 0
    assert line["test"].endswith("test_device.py::test_build_log_has_a_line_a_program_built")


def test_row_bands_cover_the_rows_once_from_first_rows_not_offsets():
    """``in_row_bands`` launches whole work-groups of rows, each band from the row its launch is given, together
    every row once: a row number, not a global offset, which would have PoCL compile the kernel twice."""
    bands = []
    kernels.in_row_bands(SimpleNamespace(finish=lambda: None), lambda size, first: bands.append((size, first)),
                         (24, 40), (8, 8))
    assert all(size[0] == 24 and size[1] % 8 == 0 and isinstance(first, int) for size, first in bands)
    assert [first for _, first in bands] == list(np.cumsum([0] + [size[1] for size, _ in bands[:-1]]))
    assert sum(size[1] for size, _ in bands) == 40
