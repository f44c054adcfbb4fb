"""Ray tracing of order 6 (``wavelet="quintic"``, docs/raytracing.md §2-§3): degree-5 pieces in the bricks,
16 samples a segment for the degree-15 integrand, against the closed-form model and the float64 oracles."""

import numpy as np
import pytest
from test_bricks import build, pool_field, smooth_rgba, smooth_volume
from test_lod import without_details
from test_raytrace import check_normals_against_finite_differences

import clwave
from clwave import TransferFunction, WaveletVolume
from clwave.device.constants import BLOCK, SUPER
from clwave.model.geometry import fine_to_world
from clwave.raytrace.reference import _content_field, classified_reference, raytrace_reference
from clwave.raytrace.shading import Phong
from clwave.raytrace.tracer import RayTracer

pytestmark = pytest.mark.opencl
QUINTIC_HAAR = ["quintic", "quintic", "quintic", "haar"]


@pytest.fixture(scope="module")
def quintic_rgba():
    rng = np.random.default_rng(3)
    data = rng.random((5, 6, 7, 4)) * np.array([1.0, 0.8, 0.6, 0.5])
    wv = WaveletVolume.from_volume(clwave.Volume(data.astype(np.float32), spacing=(1.0, 0.8, 1.2)),
                                   wavelet="quintic", levels=1)
    return wv, RayTracer(wv)


def test_quintic_bricks_equal_the_model_with_their_bounds():
    """Degree-5 pieces on bricks of every level (content clamped): values and gradients against the closed-form
    wavelet sum, and |f| within the bound of its block (partition of unity), nothing outside the bounded blocks."""
    wv = WaveletVolume.from_volume(smooth_volume(n=36, empty_corner=True), wavelet="quintic", levels=2)
    wv = wv.threshold(keep=0.1)
    field = build(wv)
    assert len(np.unique(field.levels)) >= 2  # bricks of several levels
    x0 = np.random.default_rng(7).uniform(-8, 44, (60, 3))
    world = fine_to_world(x0, 6, wv.shape, wv.spacing, wv.origin)
    model = _content_field(wv)
    ref, got = model(world, False), pool_field(wv, field, x0)
    assert np.abs(ref).max() > 0.1
    np.testing.assert_allclose(got, ref, rtol=0, atol=2e-6 * np.abs(ref).max())
    grad = pool_field(wv, field, x0[:20], derivative=True)[..., ::-1] / np.asarray(wv.spacing)[::-1]
    want = model(world[:20], True)
    np.testing.assert_allclose(grad, want, rtol=0, atol=2e-5 * np.abs(want).max())
    bound = field.bound_grid(field.pages[0])
    block = np.floor(x0 / BLOCK).astype(int) - field.origin * SUPER
    inside = np.all((block >= 0) & (block < bound.shape), axis=1)
    values = np.abs(got).max(axis=1)
    assert values[~inside].max(initial=0.0) == 0.0
    assert np.all(values[inside] <= bound[tuple(block[inside].T)] * (1 + 1e-6))


@pytest.mark.parametrize("kw", [dict(absorption=False), dict(shading=False), dict(),
                                dict(lights=[(0, 90), (120, -10)], shading=Phong(0.2, 0.6, 0.5, 8))])
def test_kernel_equals_numpy_reference(quintic_rgba, kw):
    """The float32 kernel equals the float64 oracle of the same algorithm (closed-form field and gradients)."""
    wv, tracer = quintic_rgba
    cam = clwave.Camera(30, 20, size=(3, 4))
    ref = raytrace_reference(wv, cam, tolerance=1e-3, tracer=tracer, **kw)
    got = tracer.render(cam, tolerance=1e-3, **kw)
    assert got.meta["segments"] > 0 and np.abs(ref).max() > 0.3
    assert np.max(np.abs(got.image - ref)) <= 1e-5 * max(1.0, np.abs(ref).max())


def test_wavelet_field_equals_numpy_reference(quintic_rgba):
    """The wavelet field (active lists, degree-5 piece polynomials and their derivatives) equals the float64 oracle,
    shaded with two lights."""
    wv = quintic_rgba[0].threshold(keep=0.2)
    tracer = RayTracer(wv, field="wavelet")
    cam = clwave.Camera(30, 20, size=(3, 4))
    kw = dict(lights=[(0, 90), (120, -10)], shading=Phong(0.2, 0.6, 0.5, 8))
    ref = raytrace_reference(wv, cam, tolerance=1e-3, tracer=tracer, **kw)
    got = tracer.render(cam, tolerance=1e-3, **kw)
    assert got.meta["field"] == "wavelet" and got.meta["rays_active_list_overflowed"] == 0
    assert np.abs(ref).max() > 0.3
    assert np.max(np.abs(got.image - ref)) <= 1e-5


@pytest.mark.parametrize("camera,kw", [(clwave.Camera(30, 20, size=(3, 4)), dict()),
                                       (clwave.Camera(-50, 35, size=(3, 3), perspective=True, distance=9.0),
                                        dict(shading=False)),
                                       (clwave.Camera(-50, 35, size=(3, 3), perspective=True, distance=9.0),
                                        dict(absorption=False))])
def test_images_within_tolerance_of_the_converged_float64_reference(quintic_rgba, camera, kw):
    """Shaded and X-ray, orthographic and perspective: float32 renders at 1e-2 and 1e-3 within their
    tolerance of the float64 oracle converged at 1e-7."""
    wv, tracer = quintic_rgba
    exact = raytrace_reference(wv, camera, tolerance=1e-7, tracer=tracer, **kw)
    assert np.abs(exact).max() > 0.3
    for tol in (1e-2, 1e-3):
        err = np.max(np.abs(tracer.render(camera, tolerance=tol, **kw).image - exact))
        assert err <= tol, (tol, err)


def test_normals_equal_the_normalised_finite_difference_gradient(quintic_rgba, monkeypatch):
    """The kernel's analytic gradients of degree-5 pieces shade as normals from central differences of alpha."""
    check_normals_against_finite_differences(*quintic_rgba, monkeypatch)


def test_mixed_orders_quintic_colour_with_haar_opacity():
    """Per-channel orders (quintic RGB, Haar alpha: knot lattices of both parities, half-voxel segments) against
    the oracle, emission-absorption (Haar alpha renders unshaded)."""
    rng = np.random.default_rng(5)
    data = (rng.random((6, 5, 6, 4)) * np.array([1.0, 0.8, 0.6, 0.5])).astype(np.float32)
    wv = WaveletVolume.from_volume(clwave.Volume(data), QUINTIC_HAAR, levels=1)
    tracer = RayTracer(wv)
    cam = clwave.Camera(25, -15, size=(3, 4))
    got = tracer.render(cam, tolerance=1e-3)
    ref = raytrace_reference(wv, cam, tolerance=1e-3, tracer=tracer)
    assert np.abs(ref).max() > 0.3 and got.meta["shading"].startswith("off")
    assert np.max(np.abs(got.image - ref)) <= 1e-5 * max(1.0, np.abs(ref).max())
    assert got.meta["segments_by_lattice"]["1"] > 0


def test_post_classified_quintic_against_the_oracle():
    """A scalar quintic model through a transfer function at render time, shaded (degree-15 pieces: Bernstein
    ranges, cuts at breakpoints, 8-point Gauss-Legendre depths, the 15-lane gradient series) within the tolerance
    of the brute-force float64 oracle."""
    wv = WaveletVolume.from_volume(clwave.phantom("hydrogen", n=16), wavelet="quintic", levels=1).threshold(keep=0.2)
    tr = RayTracer(wv)
    tf = TransferFunction.preset("hydrogen")
    cam = clwave.Camera(30, 20, size=8)
    ref = classified_reference(wv, cam, tf, tracer=tr)
    assert ref[..., 3].max() > 0.05
    img = tr.render(cam, tolerance=1e-3, transfer_function=tf).image
    assert np.abs(img - ref).max() <= 1e-3


def test_level_of_detail_renders_the_coarser_quintic_model():
    """lod=True: the colours of an X-ray render at detail 1 equal those of the model without the level-1 details
    (alpha is clamped at 0 at coarser details, docs/raytracing.md §8), with fewer, coarser segments."""
    rgba = smooth_rgba(n=20)
    wv = WaveletVolume.from_volume(rgba, wavelet="quintic", levels=2).threshold(keep=0.2)
    wv.content_mask = None
    tracer = RayTracer(wv, lod=True)
    cam = clwave.Camera(25, 15, size=3)
    ref = RayTracer(without_details(wv, 1)).render(cam, tolerance=1e-4, absorption=False).image
    xray = tracer.render(cam, tolerance=1e-4, detail=1, absorption=False).image
    assert np.abs(ref).max() > 1.0
    assert np.max(np.abs(xray[..., :3] - ref[..., :3])) <= 1e-4
    full, coarse = tracer.render(cam, tolerance=1e-3), tracer.render(cam, tolerance=1e-3, detail=1)
    assert coarse.meta["detail"] == 1 and coarse.meta["segments_by_lattice"]["1"] == 0
    assert coarse.meta["segments"] < full.meta["segments"]
