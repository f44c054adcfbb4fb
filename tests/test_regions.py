"""Ray tracing split into slabs of bricks (clwave/raytrace/regions.py, docs/raytracing.md §7): the slabs'
images composited in ray order equal the whole image, here and on a Dask cluster of two worker processes
whose workers open the .clw file themselves."""

import numpy as np
import pytest

import clwave
from clwave.errors import InputError
from clwave.raytrace.regions import composite, slab_order, slabs
from clwave.raytrace.tracer import RayTracer
from test_bricks import out_of_core_model

pytestmark = pytest.mark.opencl

CAMERAS = ((clwave.Camera(30, 20, size=40), {}),
           (clwave.Camera(-60, 35, size=32), dict(absorption=False)),
           (clwave.Camera(100, -80, size=32), dict(shading=False)),  # looking up along +z: slabs in reverse
           (clwave.Camera(10, 5, size=32, perspective=True, distance=8.0, fov=70), {}))  # the eye inside a slab


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    path = tmp_path_factory.mktemp("regions") / "m.clw"
    out_of_core_model().save(path)
    return clwave.WaveletVolume.open(path)


def test_slabs_cover_the_bricks_in_runs_of_about_equal_size(model):
    parts = slabs(model, 3)
    assert len(parts) == 3 and all(a < b for a, b in parts)
    assert all(b == c for (_, b), (c, _) in zip(parts[:-1], parts[1:]))  # contiguous, in order
    whole = RayTracer(model).bricks
    assert parts[0][0] <= whole.bricks[:, 0].min() and whole.bricks[:, 0].max() < parts[-1][1]


@pytest.mark.parametrize("precision,tolerance", [("double", 1e-7), ("single", 1e-3)])
def test_slab_images_composited_in_ray_order_equal_the_whole_image(model, precision, tolerance):
    """Each slab traced with a third of the tolerance; front to back over (emission-absorption) or summed
    (X-ray): within the tolerance of the whole image."""
    whole, parts = RayTracer(model), slabs(model, 3)
    tracers = [RayTracer(model, region=r) for r in parts]
    for cam, kw in CAMERAS:
        if precision == "double" and kw.get("absorption", True):  # converged: no Simpson depth limit (§2)
            kw = dict(kw, shading=False)  # at shading's jumps the whole image and the slabs' meet it differently
        want = whole.render(cam, tolerance=tolerance, precision=precision, **kw).image
        images = [t.render(cam, tolerance=tolerance / 3, precision=precision, **kw).image for t in tracers]
        ordered = [images[i] for i in slab_order(model, parts, cam)]
        got = composite(ordered, kw.get("absorption", True))
        assert np.abs(want).max() > 0.5
        assert np.max(np.abs(got - want)) <= tolerance + np.abs(want).max() * 2.0 ** -23  # images are float32


def worker_devices(client) -> list:
    """The device memory each worker process's OpenCL device reports (the one it rendered on)."""
    return list(client.run(lambda: clwave.ComputeContext.get(None).info.global_mem).values())


def test_on_a_local_cluster_of_two_worker_processes(model):
    """clwave.raytrace(scheduler=client): the one-machine image within the tolerance, for every kind of view;
    clwave.splat(scheduler=client): the sum of the workers' shares of the coefficients, the one-machine image
    to rounding (with coarse framebuffers too)."""
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster, \
            Client(cluster) as client:
        # what the client's periodic refresh (every 2 s) leaves there, which the workers are not counted from
        client.scheduler_info = lambda *args, **kwargs: {"n_workers": 2, "workers": {}}
        for cam, kw in CAMERAS:
            want = clwave.raytrace(model, cam, tolerance=1e-3, **kw)
            got = clwave.raytrace(model, cam, tolerance=1e-3, scheduler=client, **kw)
            assert got.meta["workers"] == 2 and len(got.meta["slabs"]) == 2
            assert np.abs(want.image).max() > 0.5 and np.max(np.abs(got.image - want.image)) <= 1e-3
            # two workers on this machine: each plans for half the device as the workers see it (PoCL's is this
            # machine's memory, of which it reports a part that changes with what is free when a process starts)
            assert len(got.meta["device_budget"]) == 2
            assert max(got.meta["device_budget"]) <= max(worker_devices(client)) // 2
        for cam, kw in ((clwave.Camera(30, 20, size=40), {}), (clwave.Camera(-70, 10, size=64), dict(coarse=2e-2))):
            want = clwave.splat(model, cam, **kw)
            got = clwave.splat(model, cam, scheduler=client, **kw)
            assert got.meta["workers"] == 2 and got.meta["coefficients"] == want.meta["coefficients"]
            assert max(got.meta["device_budget"]) <= max(worker_devices(client)) // 2
            assert np.max(np.abs(got.image - want.image)) <= 1e-5 * np.abs(want.image).max()
        assert client.status == "running"


def test_workers_on_one_machine_share_its_device():
    from clwave.cluster import worker_cap
    from clwave.device.context import ComputeContext

    total = ComputeContext.get(None).info.global_mem
    assert worker_cap(None, "2GiB", 1) == "2GiB"  # alone: as given
    assert worker_cap(None, None, 1) is None
    assert worker_cap(None, None, 3) == total // 3
    assert worker_cap(None, "1MiB", 2) == 2 ** 20  # a cap below the share stands
    assert worker_cap(None, 2 * total, 2) == total // 2


def test_a_cluster_needs_a_model_opened_from_a_file(model, monkeypatch):
    """Refused before any worker starts."""
    import clwave.schedulers

    monkeypatch.setattr(clwave.schedulers, "client_for", None)  # starting a cluster would fail the test
    with pytest.raises(InputError, match=r"\.clw file"):
        clwave.raytrace(model.threshold(keep=0.5), clwave.Camera(size=8), scheduler=1)
    for bad in (dict(field="wavelet"), dict(tolerance=0), dict(device_memory="2GB"), dict(lights=(30, 40))):
        with pytest.raises(InputError):
            clwave.raytrace(model, clwave.Camera(size=8), scheduler=1, **bad)


@pytest.mark.parametrize("region,field", [("ab", "bspline"), ((0,), "bspline"), ((5, 2), "bspline"),
                                          ((0, 1.5), "bspline"), ((0, 1), "wavelet")])
def test_bad_regions_are_refused(model, region, field):
    with pytest.raises(InputError, match="region="):
        RayTracer(model, region=region, field=field)


def test_command_line_renders_a_clw_file_on_worker_processes(model, capsys, tmp_path):
    """--workers N with a .clw input: the images of the API on a cluster, ray traced and splatted; a model the
    file does not hold as it is (--threshold) is refused before any worker starts."""
    from test_cli import run

    path, raw = model.source[0], tmp_path / "x.npy"
    code, out, err = run(capsys, "render", path, "--method", "raytrace", "--workers", "2", "--size", "24",
                         "--tolerance", "1e-3", "-o", str(tmp_path / "x.png"), "--raw", str(raw))
    assert code == 0, err
    want = clwave.raytrace(model, clwave.Camera(size=24), tolerance=1e-3).image
    assert np.max(np.abs(np.load(raw) - want)) <= 1e-3
    code, out, err = run(capsys, "render", path, "--workers", "2", "--size", "24", "-o", str(tmp_path / "y.png"),
                         "--raw", str(raw), "--force")
    assert code == 0, err
    want = clwave.splat(model, clwave.Camera(size=24)).image
    assert np.max(np.abs(np.load(raw) - want)) <= 1e-5 * np.abs(want).max()
    code, out, err = run(capsys, "render", path, "--workers", "2", "--threshold", "0.1", "-o", str(tmp_path / "z.png"))
    assert code == 2 and "--threshold" in err and err.count("\n") == 1 and not (tmp_path / "z.png").exists()
