"""Ray tracing (paper §3): analytic integrals, the NumPy reference, X-ray vs splatting, bad input."""

import dataclasses

import numpy as np
import pytest
from scipy.special import erf

import clwave
from clwave.raytrace.reference import raytrace_reference
from clwave.device.constants import SUPER
from clwave.model.geometry import world_to_fine
from clwave.raytrace.bounds import content_cells, superblocks
from clwave.raytrace.quadrature import gradient_samples, sample_points, sample_tables
from clwave.raytrace.shading import Phong
from clwave.raytrace.tracer import RayTracer
from clwave.splat.reference import exact_xray
from test_hardening import LAUNCHED, interrupted
from test_splat_memory import turns_with

TOLERANCES = [1e-2, 3e-3, 1e-3, 3e-4, 1e-4]


def rgba_volume(q, alpha, spacing=(1.0, 1.0, 1.0)):
    """A 4-channel volume with q in R, G, B and alpha in A."""
    return clwave.Volume(np.stack([q, q, q, alpha], axis=-1).astype(np.float32), spacing=spacing)


def errors_over_tolerances(tracer, camera, exact, **kw):
    errs = []
    for tol in TOLERANCES:
        image = tracer.render(camera, tolerance=tol, shading=False, **kw).image
        err = float(np.max(np.abs(image - exact)))
        assert err <= tol, f"error {err:.2e} above tolerance {tol:.0e}"
        errs.append(err)
    return errs


@pytest.mark.parametrize("degree", [0, 3, 6, 9, 15])
def test_sample_tables_are_exact_for_polynomials_of_the_segment_degree(degree):
    """From the samples of a random polynomial of the segment's degree: its integrals from -1 to
    xi = -1 + p/4 (p = 1..8), its Chebyshev series, and from lanes 0..8 (0..14 for degree 15) the series of a
    polynomial one degree lower (the gradient), against numpy's polynomial arithmetic."""
    rng = np.random.default_rng(degree)
    poly, lower = (np.polynomial.Polynomial(rng.normal(size=n)) for n in (degree + 1, max(degree, 1)))
    xi = sample_points(degree)
    assert len(xi) == max(degree + 1, 9) and np.allclose(xi[:9], -1.0 + np.r_[np.arange(1, 9), 0] / 4.0)
    ng = gradient_samples(len(xi))  # lanes 0..ng-1 give the gradient, of degree one less
    assert ng >= degree and len(np.unique(xi)) == len(xi)
    nodes, weights = sample_tables(degree)
    n = len(xi)
    assert weights.flags.c_contiguous and weights.shape == (n, 8)  # the kernel reads rows of 8
    np.testing.assert_allclose(nodes[:n], xi)
    np.testing.assert_allclose(poly(xi) @ weights, poly.integ(lbnd=-1)(-1.0 + np.arange(1, 9) / 4.0), atol=1e-12)
    field_series = nodes[n:n + n * n].reshape(n, n) @ poly(xi)
    gradient_series = nodes[n + n * n:].reshape(ng, ng) @ lower(xi[:ng])
    x = np.linspace(-1, 1, 7)
    np.testing.assert_allclose(np.polynomial.chebyshev.chebval(x, field_series), poly(x), atol=1e-12)
    np.testing.assert_allclose(np.polynomial.chebyshev.chebval(x, gradient_series), lower(x), atol=1e-12)


def test_constant_slab_matches_closed_form():
    """Haar box of q = 2, alpha = 0.7, length L = 6 * 3 along x: I = q/alpha (1 - e^{-alpha L})."""
    n, q, alpha, dx = 6, 2.0, 0.7, 3.0
    vol = rgba_volume(np.full((4, 4, n), q), np.full((4, 4, n), alpha), spacing=(1.0, 1.0, dx))
    tracer = RayTracer(clwave.WaveletVolume.from_volume(vol, wavelet="haar", levels=1))
    L = n * dx
    exact = np.array([q / alpha * (1 - np.exp(-alpha * L))] * 3 + [1 - np.exp(-alpha * L)])
    errs = errors_over_tolerances(tracer, clwave.Camera(0, 0, size=1), exact)
    assert errs[-1] < errs[0]  # the error falls over the decade


def test_linear_opacity_matches_erf_form():
    """Linear B-splines with alpha = a x, q = 1.5 (ramping in over the first voxel), along +x."""
    n, a, q = 10, 0.8, 1.5
    x = np.arange(n) + 1.0  # voxel i sits at fine x = i + j/2 = i + 1 for j = 2
    alpha = np.broadcast_to(a * x, (4, 4, n))
    vol = rgba_volume(np.full((4, 4, n), q), alpha)
    tracer = RayTracer(clwave.WaveletVolume.from_volume(vol, wavelet="linear", levels=1))
    # alpha(x) = a x on [0, n]; q ramps as q x on [0, 1]; what lies beyond x = n is below e^{-a n^2 / 2}
    ramp = q * (1 - np.exp(-a / 2)) / a
    body = q * np.sqrt(np.pi / (2 * a)) * (erf(n * np.sqrt(a / 2)) - erf(np.sqrt(a / 2)))
    exact = np.array([ramp + body] * 3 + [1.0])
    errs = errors_over_tolerances(tracer, clwave.Camera(180, 0, size=1), exact)
    assert errs[-1] < errs[0]


def test_emission_proportional_to_opacity_gives_one_minus_transmittance():
    """q = c alpha through a random cubic-spline volume: I = c (1 - e^{-A}) for any alpha, A exact."""
    rng = np.random.default_rng(7)
    alpha = rng.random((8, 9, 10)) * 0.6
    c = 3.0
    wv = clwave.WaveletVolume.from_volume(rgba_volume(c * alpha, alpha, spacing=(1.0, 0.9, 1.1)),
                                          wavelet="cubic", levels=1)
    cam = clwave.Camera(30, 20, size=(6, 7), extent=float(np.linalg.norm(np.multiply((10, 9, 8), (1.1, 0.9, 1.0)))))
    A = exact_xray(wv.reconstruct().data[..., 3], 4, wv.spacing, wv.origin, cam.view(wv))[..., 0]
    exact = np.concatenate([np.repeat((c * (1 - np.exp(-A)))[..., None], 3, -1), (1 - np.exp(-A))[..., None]], -1)
    errs = errors_over_tolerances(RayTracer(wv), cam, exact)
    assert max(errs) > 0 and errs[-1] <= errs[0]


@pytest.fixture(scope="module")
def small_rgba():
    rng = np.random.default_rng(3)
    data = rng.random((5, 6, 7, 4)) * np.array([1.0, 0.8, 0.6, 0.5])
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data.astype(np.float32), spacing=(1.0, 0.8, 1.2)),
                                          wavelet="cubic", levels=1)
    return wv, RayTracer(wv)


@pytest.fixture(scope="module")
def small_wavelet_tracer(small_rgba):
    return RayTracer(small_rgba[0], field="wavelet")


@pytest.mark.parametrize("field", ["bspline", "wavelet"])
@pytest.mark.parametrize("kw", [dict(absorption=False), dict(shading=False), dict(),
                                dict(lights=[(0, 90), (120, -10)], shading=Phong(0.2, 0.6, 0.5, 8)),
                                # shininess not a whole number up to 64: powers through logarithms, not squaring
                                dict(lights=[(40, 30)], shading=Phong(0.2, 0.6, 0.9, 7.5)),
                                dict(lights=[(40, 30)], shading=Phong(0.2, 0.6, 0.9, 80))])
def test_kernel_equals_numpy_reference(small_rgba, small_wavelet_tracer, kw, field):
    wv, tracer = small_rgba
    tracer = small_wavelet_tracer if field == "wavelet" else tracer
    cam = clwave.Camera(30, 20, size=(3, 4))
    ref = raytrace_reference(wv, cam, tolerance=1e-3, tracer=tracer, **kw)
    got = tracer.render(cam, tolerance=1e-3, **kw)
    assert got.meta["field"] == field
    assert np.max(np.abs(got.image - ref)) <= 1e-5 * max(1.0, np.abs(ref).max())


@pytest.mark.parametrize("kw", [dict(), dict(absorption=False)])
def test_kernel_equals_reference_with_superblocks_as_regions(monkeypatch, kw):
    """Kernel and reference cross superblocks as single regions alike: first the nearly empty ones
    of a volume with a faint end, then (the coarse bound raised 1e9-fold) the ones that hold its
    visible content too, where R and the skipping change the march."""
    rng = np.random.default_rng(4)
    data = rng.random((8, 8, 40, 4)) * 1e-10
    data[:, :, :8] = rng.random((8, 8, 8, 4)) * 0.5
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data.astype(np.float32)), wavelet="cubic", levels=1)
    tracer = RayTracer(wv)
    sup = tracer.super_bound_host
    assert np.any((sup > 0) & (sup <= tracer.coarse_bound(1e-3)))
    cam = clwave.Camera(80, 10, size=(3, 4))
    ref = raytrace_reference(wv, cam, tolerance=1e-3, tracer=tracer, **kw)
    got = tracer.render(cam, tolerance=1e-3, **kw)
    assert np.abs(ref).max() > 0.05
    assert np.max(np.abs(got.image - ref)) <= 1e-5 * np.abs(ref).max()

    bound = tracer.coarse_bound
    monkeypatch.setattr(tracer, "coarse_bound", lambda tol: bound(tol) * 1e9)
    assert np.any((sup > bound(1e-3)) & (sup <= tracer.coarse_bound(1e-3)))
    ref = raytrace_reference(wv, cam, tolerance=1e-3, tracer=tracer, **kw)
    coarse = tracer.render(cam, tolerance=1e-3, **kw)
    assert coarse.meta["segments"] != got.meta["segments"]
    assert np.max(np.abs(coarse.image - ref)) <= 1e-5 * np.abs(ref).max()


@pytest.mark.parametrize("kw", [dict(shading=False), dict()])
def test_kernel_equals_reference_where_the_field_dips_below_zero(kw):
    """Interpolating prefilter: the spline overshoots below 0 between voxels.  Alpha is clamped at
    the samples, q wherever it is evaluated (its series stays the polynomial)."""
    rng = np.random.default_rng(3)
    data = (rng.random((5, 6, 7, 4)) * np.array([1.0, 0.8, 0.6, 0.5])).astype(np.float32)
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data, spacing=(1.0, 0.8, 1.2)), wavelet="cubic",
                                          levels=1, interpolate=True)
    assert wv.evaluate(np.random.default_rng(0).uniform(-2, 2, (4000, 3))).min() < -0.1
    tracer, cam = RayTracer(wv), clwave.Camera(30, 20, size=(3, 4))
    ref = raytrace_reference(wv, cam, tolerance=1e-4, tracer=tracer, **kw)
    got = tracer.render(cam, tolerance=1e-4, **kw)
    assert np.max(np.abs(got.image - ref)) <= 1e-5 * max(1.0, np.abs(ref).max())


@pytest.mark.parametrize("field", ["bspline", "wavelet"])
def test_perspective_kernel_equals_reference_and_eye_inside_integrates_from_eye(small_rgba, small_wavelet_tracer,
                                                                                 field):
    wv, tracer = small_rgba
    tracer = small_wavelet_tracer if field == "wavelet" else tracer
    cam = clwave.Camera(-40, 10, size=(3, 3), perspective=True, distance=4.0, fov=40)
    ref = raytrace_reference(wv, cam, tolerance=1e-3, tracer=tracer)
    assert np.max(np.abs(tracer.render(cam, tolerance=1e-3).image - ref)) <= 1e-5
    # an eye in the middle of a constant Haar box sees q/alpha (1 - e^{-alpha d}), d = distance to the wall
    vol = rgba_volume(np.full((6, 6, 6), 1.0), np.full((6, 6, 6), 0.5))
    box = RayTracer(clwave.WaveletVolume.from_volume(vol, wavelet="haar", levels=0), field=field)
    inside = clwave.Camera(0, 0, size=1, perspective=True, distance=1.0, fov=10)  # eye at x = 1, looks along -x
    img = box.render(inside, tolerance=1e-4, shading=False).image[0, 0]
    d = 1.0 + 3.0
    assert np.allclose(img[:3], 2.0 * (1 - np.exp(-0.5 * d)), atol=1e-4)
    assert np.isclose(img[3], 1 - np.exp(-0.5 * d), atol=1e-4)


def test_xray_mode_matches_splatting():
    vol = clwave.phantom("hydrogen", n=16)
    wv = clwave.WaveletVolume.from_volume(vol, wavelet="cubic", levels=2)
    for cam in (clwave.Camera(30, 20, size=32), clwave.Camera(0, 0, size=32)):
        ray = clwave.raytrace(wv, cam, absorption=False)
        spl = clwave.splat(wv, cam)
        assert ray.meta["mode"] == "xray" and ray.image.shape == spl.image.shape
        assert np.max(np.abs(ray.image - spl.image)) <= 5e-3 * spl.image.max()


def test_a_tolerance_above_every_line_integral_is_told_with_one_that_draws():
    """Micrometre voxels of 1: every line integral is at most 1e-6 x the diagonal (13.9e-6), below the default
    absolute tolerance, and skipping passed every block (a black image, silently). Told once per tracer and
    tolerance, naming a tolerance that draws the closed form: 8 voxels of 1e-6 through the centre, 8e-6."""
    import warnings
    from clwave.errors import ClwaveWarning

    wv = clwave.WaveletVolume.from_volume(clwave.Volume(np.ones((8, 8, 8)), spacing=1e-6), "linear", levels=1)
    tracer, camera = RayTracer(wv), clwave.Camera(0, 0, size=16)
    with pytest.warns(ClwaveWarning, match=r"at most 1.39e-05 .* below the absolute tolerance 0.001, so the image may "
                                           r"be black: give a tolerance well below it, e.g. tolerance=1e-08") as told:
        tracer.render(camera, tolerance=1e-3, absorption=False)
    assert told[0].message.cli.endswith("e.g. --tolerance 1e-08") and told[0].filename == __file__  # the caller's
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # said once per tracer and tolerance; a tolerance below the bound: silent
        tracer.render(camera, tolerance=1e-3, absorption=False)
        image = tracer.render(camera, tolerance=1e-8, absorption=False).image
    assert np.isclose(image.max(), 8e-6, rtol=1e-5)
    # another bound, told again: the grey preset's opacities per world unit (a micrometre here), not per voxel
    grey_per_world_unit = clwave.TransferFunction.preset("grey", opacity_unit=1.0)
    with pytest.warns(ClwaveWarning, match="below the absolute tolerance 0.001"):
        tracer.render(camera, tolerance=1e-3, transfer_function=grey_per_world_unit)


@pytest.mark.parametrize("origin", [(0, 0, 0), (-3, 5, -9)])
def test_superblocks_hold_the_largest_block_bound(origin):
    """Each superblock's bound against the largest bound of the blocks inside it, block by block."""
    bound = np.random.default_rng(2).random((9, 6, 11)).astype(np.float32)
    sup, s_origin = superblocks(bound, origin)
    for idx in np.ndindex(bound.shape):
        block = np.array(idx) + origin
        assert sup[tuple(block // SUPER - s_origin)] >= bound[idx]
    for sidx in np.ndindex(sup.shape):
        first = (np.array(sidx) + s_origin) * SUPER - origin
        inside = tuple(slice(max(f, 0), max(f + SUPER, 0)) for f in first)
        assert sup[sidx] == bound[inside].max(initial=0.0)


def test_repeat_renders_are_bit_identical(small_rgba):
    _, tracer = small_rgba
    cam = clwave.Camera(10, 50, size=8)
    assert np.array_equal(tracer.render(cam).image, tracer.render(cam).image)


def test_a_render_in_turns_is_the_render_whatever_is_rendered_between_its_bands():
    """``RayTracer.rendering`` (a viewer's saved image, docs/viewer.md §5), another render of the same tracer between
    every two of its bands of rows, each of another view, size, transfer function, detail and clip: bit for bit
    ``render`` of the view (a ray is one work-item's; the classification and detail's tables of a render its own)."""
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=24), levels=2).threshold(keep=0.3)
    tracer = RayTracer(wv, lod=True)
    cam, tf = clwave.Camera(35, 25, size=(72, 40)), clwave.TransferFunction.preset("hydrogen", window=(0.05, 0.7))
    expect = tracer.render(cam, tolerance=1e-3, transfer_function=tf).image
    got, between = turns_with(tracer.rendering(cam, tolerance=1e-3, transfer_function=tf), lambda i: tracer.render(
        clwave.Camera(-40 * i, 10, size=17 + i), tolerance=1e-2, detail=(i + 1) % 3,
        transfer_function=clwave.TransferFunction.preset("hydrogen", window=(0.1 * (i + 1), 0.9)),
        clip=clwave.Clip(planes=[((0, 0, 0), (1, 0, 0))])))
    assert between >= 1 and np.abs(expect).max() > 0.1 and np.array_equal(got.image, expect)


def test_big_image_equals_its_centre_crop(small_rgba):
    """A 128^2 image (PoCL's default work-groups for it once overflowed the threads' stacks) against
    a 4^2 render of its centre pixels: the same rays, the same values."""
    wv, tracer = small_rgba
    big = clwave.Camera(25, 15, size=128)
    crop = clwave.Camera(25, 15, size=4, extent=big.view(wv).pixel * 4)
    got = tracer.render(big, tolerance=1e-3).image
    assert np.abs(got).max() > 0.05
    np.testing.assert_allclose(got[62:66, 62:66], tracer.render(crop, tolerance=1e-3).image, rtol=0, atol=1e-6)


def test_shading_meta_and_haar_unshaded():
    vol = rgba_volume(np.full((4, 4, 4), 1.0), np.full((4, 4, 4), 0.5))
    res = clwave.raytrace(clwave.WaveletVolume.from_volume(vol, wavelet="haar", levels=1),
                          clwave.Camera(20, 10, size=4))
    assert res.meta["shading"].startswith("off: the Haar basis")
    assert res.meta["field"] == "bspline" and res.image.shape == (4, 4, 4)


def test_zero_lights_leave_the_ambient_term(small_rgba):
    _, tracer = small_rgba
    cam = clwave.Camera(30, 20, size=4)
    ambient_only = tracer.render(cam, lights=[]).image
    dark = tracer.render(cam, shading=Phong(ambient=0.3, diffuse=0.0, specular=0.0)).image
    assert np.allclose(ambient_only, dark, atol=1e-6)
    assert not np.allclose(ambient_only, tracer.render(cam).image)


def test_lights_without_shading_are_refused(small_rgba, tmp_path, capsys):
    """Lights change nothing on an unshaded image or an X-ray: given there, they are refused in one line, not
    ignored (the API, and the command line before any set-up)."""
    from test_cli import run

    _, tracer = small_rgba
    cam = clwave.Camera(30, 20, size=4)
    for kwargs in (dict(shading=False), dict(absorption=False)):
        with pytest.raises(clwave.InputError, match="light a shaded image"):
            tracer.render(cam, lights=[(90, 0)], **kwargs)
        assert tracer.render(cam, lights=[], **kwargs).image.shape[:2] == (4, 4)  # none: nothing to refuse
    path = tmp_path / "v.npy"
    np.save(path, np.random.default_rng(0).random((6, 6, 6)).astype(np.float32))
    code, out, err = run(capsys, "render", str(path), "--method", "raytrace", "--tf", "grey", "--no-shading",
                         "--light", "90,0", "-o", str(tmp_path / "x.png"))
    assert code == 2 and "--light lights a shaded image" in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "x.png").exists()


def test_simpson_stops_at_its_depth_limit_on_a_shading_jump():
    """Along +x through a ridge of alpha, the headlight's diffuse term drops from lit to dark where the
    gradient turns (mid-segment): no panel size meets 1e-6 there, so refinement must stop at
    SIMPSON_DEPTH halvings (it once refined without end) and still agree with the reference."""
    profile = np.zeros(12)
    profile[4:9] = [0.15, 0.5, 0.4, 0.15, 0.025]
    vol = rgba_volume(np.ones((6, 6, 12)), np.broadcast_to(profile, (6, 6, 12)))
    wv = clwave.WaveletVolume.from_volume(vol, wavelet="cubic", levels=1)
    tracer, cam = RayTracer(wv), clwave.Camera(180, 0, size=1)
    for tol in (1e-4, 1e-6):
        got = tracer.render(cam, tolerance=tol)
        assert got.meta["rays_at_simpson_depth_limit"] == 1
        # 5 per segment, 2 per halving: the jump costs about 4 SIMPSON_DEPTH, smooth panels a few each
        assert got.meta["integrand_evaluations"] <= 40 * got.meta["segments"]
        ref = raytrace_reference(wv, cam, tolerance=tol, tracer=tracer)
        assert np.max(np.abs(got.image - ref)) <= 1e-5 * np.abs(ref).max()


def test_view_that_misses_gives_an_empty_image(small_rgba):
    _, tracer = small_rgba
    res = tracer.render(clwave.Camera(0, 0, size=6, target=(0.0, 500.0, 0.0), extent=5.0))
    assert np.all(res.image == 0) and res.meta["segments"] == 0


@pytest.mark.parametrize("tol", [0, -1e-3, float("nan")])
def test_bad_tolerance(small_rgba, tol):
    with pytest.raises(clwave.InputError, match="tolerance"):
        small_rgba[1].render(clwave.Camera(size=4), tolerance=tol)


def test_scalar_volume_needs_classification():
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=8), wavelet="linear", levels=1)
    with pytest.raises(clwave.InputError, match="classify it first"):
        clwave.raytrace(wv, clwave.Camera(size=4))
    assert clwave.raytrace(wv, clwave.Camera(size=4), absorption=False).image.shape == (4, 4, 1)


@pytest.mark.parametrize("field", ["bspline", "wavelet"])
def test_too_little_device_memory_is_reported(monkeypatch, field):
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=8), wavelet="linear", levels=1)
    cc = clwave.ComputeContext.get()
    monkeypatch.setattr(cc, "info", dataclasses.replace(cc.info, global_mem=1000))
    with pytest.raises(clwave.DeviceMemoryError, match="need"):
        RayTracer(wv, field=field)


def test_budget_holds_on_a_sparse_thresholded_volume():
    """Quadrature, early termination, skipped near-empty blocks and segments shaded at the midpoint of their
    shading range together stay within tolerance."""
    rgba = clwave.TransferFunction.preset("hydrogen").classify(clwave.phantom("hydrogen", n=24))
    wv = clwave.WaveletVolume.from_volume(rgba, wavelet="cubic", levels=2).threshold(keep=0.05)
    tracer = RayTracer(wv)
    cam = clwave.Camera(30, 20, size=12)
    converged = tracer.render(cam, tolerance=1e-7, precision="double").image
    for tol in (1e-2, 1e-3):
        res = tracer.render(cam, tolerance=tol)
        assert np.max(np.abs(res.image - converged)) <= tol
        assert 0 < res.meta["segments_shaded_at_midpoint"] < res.meta["segments"]  # both kinds of shaded segment
    assert res.meta["segments"] < tracer.render(cam, tolerance=1e-7).meta["segments"]  # blocks were skipped


def sparse_rgba(wavelet, levels=2, keep=0.3, seed=5):
    rng = np.random.default_rng(seed)
    data = rng.random((9, 10, 11, 4)) * np.array([1.0, 0.8, 0.6, 0.4])
    data[:, :, :3] = 0  # an empty slab to skip
    vol = clwave.Volume(data.astype(np.float32), spacing=(1.0, 0.8, 1.2))
    return clwave.WaveletVolume.from_volume(vol, wavelet=wavelet, levels=levels).threshold(keep=keep)


@pytest.mark.parametrize("wavelet", ["cubic", "linear", "haar", ["cubic", "cubic", "cubic", "haar"]])
def test_wavelet_field_equals_bspline_field(wavelet):
    """Active lists over the kept coefficients and the expanded fine grids: one function, one image.
    (Without the content mask: only the B-spline field zeroes the coefficients of empty voxels.)"""
    wv = sparse_rgba(wavelet)
    wv.content_mask = None
    fast, reference = RayTracer(wv), RayTracer(wv, field="wavelet")
    for cam, kw in ((clwave.Camera(30, 20, size=10), {}), (clwave.Camera(0, 0, size=10), dict(absorption=False)),
                    (clwave.Camera(-60, 35, size=8, perspective=True, distance=12.0), dict(shading=False))):
        a = fast.render(cam, tolerance=1e-6, precision="double", **kw)
        b = reference.render(cam, tolerance=1e-6, precision="double", **kw)
        assert (a.meta["field"], b.meta["field"]) == ("bspline", "wavelet")
        assert b.meta["rays_active_list_overflowed"] == 0
        assert np.abs(a.image).max() > 0.1
        assert np.max(np.abs(a.image - b.image)) <= 1e-5


def test_shaded_wavelet_field_is_the_unclamped_model_within_tolerance():
    """A classified box with every coefficient kept (a new user's trial): the shaded wavelet field is the float64
    oracle of the unclamped model (the tracer's field, docs/raytracing.md §4) within the tolerance, the B-spline
    field the oracle of the clamped one; the two models' shaded images differ by more than the tolerance there, so
    comparing the wavelet field with the clamped oracle is no test of its shading."""
    data = np.zeros((10, 12, 14, 4), np.float32)
    data[3:7, 3:9, 4:11] = (0.9, 0.7, 0.5, 0.6)
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data, spacing=(2.0, 1.0, 0.5)), levels=2)
    assert wv.content_mask is not None
    cam, tol = clwave.Camera(30, 20, size=6), 1e-4  # 6^2 rays cross the box's faces and edges too
    images = {}
    for field in ("bspline", "wavelet"):
        tracer = RayTracer(wv, field=field)
        images[field] = ref = raytrace_reference(wv, cam, tolerance=tol, tracer=tracer)
        assert np.abs(tracer.render(cam, tolerance=tol).image - ref).max() <= tol, field
    assert images["bspline"][..., 3].max() > 0.3 and np.abs(images["bspline"] - images["wavelet"]).max() > tol


def brute_force_census(wv, x_fine):
    """(count, sum of id + 1, sum of (id + 1)^2 mod 2^32) of the kept coefficients whose supports contain x.

    ``x_fine``: grid-0 fine coordinates (x, y, z); ids index the concatenated dense bands.
    """
    j0 = wv.groups[0].wavelet.order
    count, total, total2, offset = 0, np.uint32(0), np.uint32(0), 0
    for g in wv.groups:
        wav = g.wavelet
        for band, arr in zip(g.bands, g.dense_bands()):
            corner = np.array([wav.offset(letter, band.level) + (j0 - wav.order) / 2.0 for letter in band.key])
            length = 2.0 ** band.level * np.array([wav.support(letter) for letter in band.key])
            k = np.argwhere(np.any(arr != 0, axis=3))  # (z, y, x)
            lo = corner + 2.0 ** band.level * k
            inside = np.all((lo <= x_fine[::-1]) & (x_fine[::-1] < lo + length), axis=1)
            ids = (offset + np.ravel_multi_index(k[inside].T, arr.shape[:3]) + 1).astype(np.uint64)
            count += len(ids)
            total += np.uint32(ids.sum() % 2**32)
            total2 += np.uint32((ids * ids).sum() % 2**32)
            offset += arr[..., 0].size
    return count, int(total), int(total2)


def test_active_list_equals_the_brute_force_set_of_supports():
    """On each traced segment, the kernel's active list is every kept coefficient whose support holds the midpoint."""
    wv = sparse_rgba("cubic", keep=0.2)
    cam = clwave.Camera(25, 15, size=6)
    tracer = RayTracer(wv, field="wavelet")
    res = tracer.render(cam, tolerance=1e-4, trace=40)
    census = res.meta["active_trace"].view(np.uint32)  # (H, W, 40, 4)
    t_mids = res.meta["active_trace"][..., 3].view(np.float32)
    view = cam.view(wv)
    scale = 1.0 / np.array(wv.spacing[::-1])
    offset = -np.asarray(wv.origin) * scale + (np.array(wv.shape[::-1]) - 1) / 2.0 + 2.0
    checked = nonempty = 0
    for r, c in np.ndindex(*view.size):
        p = view.target + (c + 0.5 - view.size[1] / 2) * view.pixel * view.u + \
            (view.size[0] / 2 - r - 0.5) * view.pixel * view.v
        for (count, total, total2, t_bits), t_mid in zip(census[r, c], t_mids[r, c]):
            if (count, total, total2, t_bits) == (0, 0, 0, 0):
                continue
            x = (p - float(t_mid) * view.n) * scale + offset
            assert (count, total, total2) == brute_force_census(wv, x), (r, c, t_mid)
            checked += 1
            nonempty += count > 0
    assert checked > 200 and nonempty > 100


def test_active_list_overflow_falls_back_to_every_index():
    wv = sparse_rgba("cubic")
    cam = clwave.Camera(30, 20, size=8)
    full = RayTracer(wv, field="wavelet").render(cam, tolerance=1e-4)
    tiny = RayTracer(wv, field="wavelet", active=4).render(cam, tolerance=1e-4)
    assert full.meta["rays_active_list_overflowed"] == 0 < tiny.meta["rays_active_list_overflowed"]
    assert np.max(np.abs(full.image - tiny.image)) <= 1e-6


def test_wavelet_block_bounds_hold_the_field():
    """The wavelet field's per-block bound, summed from |c| and the prototypes' maxima, bounds |f| there."""
    wv = sparse_rgba("cubic", keep=0.1)
    tracer = RayTracer(wv, field="wavelet")
    bound = tracer.block_bound.get()
    rng = np.random.default_rng(0)
    pts = (rng.random((4000, 3)) - 0.5) * np.array([16.0, 12.0, 12.0])
    fine = world_to_fine(pts, 4, wv.shape, wv.spacing, wv.origin)  # (z, y, x)
    # the field the tracer renders: the model where the volume's content reaches, else empty
    cell = np.floor(fine).astype(int) - tracer.content_origin
    reached = np.all((cell >= 0) & (cell < tracer.content_cells.shape), axis=1)
    reached[reached] = tracer.content_cells[tuple(cell[reached].T)] > 0
    vals = np.abs(wv.evaluate(pts)).max(axis=1) * reached
    blk = np.floor(fine / 8).astype(int) - tracer.occ_origin
    inside = np.all((blk >= 0) & (blk < bound.shape), axis=1)
    assert vals[~inside].max(initial=0.0) == 0.0
    assert np.all(vals[inside] <= bound[tuple(blk[inside].T)] * (1 + 1e-6))
    assert vals.max() > 0.1


def test_unknown_field_is_refused():
    with pytest.raises(clwave.InputError, match="field"):
        RayTracer(sparse_rgba("linear", levels=1), field="octree")


@pytest.mark.parametrize("field", ["bspline", "wavelet"])
def test_normals_equal_the_normalised_finite_difference_gradient(small_rgba, small_wavelet_tracer, monkeypatch,
                                                                 field):
    """Shaded kernel image == the NumPy reference whose normals come from central differences of alpha."""
    wv, tracer = small_rgba
    check_normals_against_finite_differences(wv, small_wavelet_tracer if field == "wavelet" else tracer, monkeypatch)


def check_normals_against_finite_differences(wv, tracer, monkeypatch, h=1e-4):
    """The shaded kernel image equals the oracle's whose gradients come from central differences of the model."""
    cam = clwave.Camera(30, 20, size=(3, 4))
    kw = dict(tolerance=1e-4, lights=[(10, 60), (200, 0)], shading=Phong(0.1, 0.8, 0.6, 12))
    got = tracer.render(cam, **kw).image
    evaluate = wv.evaluate

    def central_differences(points, method="auto"):  # the oracle asks for the band sum (method="bands")
        pts = np.atleast_2d(np.asarray(points, float))
        return np.stack([(evaluate(pts + s, method) - evaluate(pts - s, method)) / (2 * h) for s in np.eye(3) * h],
                        axis=-1)

    monkeypatch.setattr(wv, "gradient", central_differences)
    ref = raytrace_reference(wv, cam, tracer=tracer, **kw)
    assert np.abs(ref[..., :3]).max() > 0.05
    assert np.max(np.abs(got - ref)) <= 1e-5  # the same algorithm: as close as the analytic-normal reference


def classified_ball(n=32, radius=9.0):
    """An RGBA ball with a sharp edge in an empty margin (a classified scan's shape)."""
    z, y, x = np.mgrid[:n, :n, :n] - (n - 1) / 2
    inside = (x ** 2 + 1.3 * y ** 2 + 0.8 * z ** 2) < radius ** 2
    alpha = np.where(inside, 0.15 + 0.05 * np.sin(x / 3.0), 0.0)
    return clwave.Volume(np.stack([alpha * 0.9, alpha * 0.6, alpha * 0.3, alpha], -1).astype(np.float32))


def test_empty_space_stays_empty_and_is_skipped_with_a_thresholded_model():
    """Truncated wavelets ring where the classified volume is zero; the tracer renders no haze there
    (docs/raytracing.md §4) and skips it as fast as for the full model."""
    vol = classified_ball()
    full = clwave.WaveletVolume.from_volume(vol, "cubic", levels=2)
    thin = full.threshold(keep=0.05)
    points = vol.voxel_to_world(np.argwhere(vol.content_mask() == 0))
    assert thin.evaluate(points)[:, 3].max() > 1e-3  # the model itself rings in the empty margin
    cam = clwave.Camera(30, 20, size=48)
    a, b = (RayTracer(wv).render(cam, tolerance=1e-4) for wv in (full, thin))
    empty = np.all(a.image == 0, axis=2)  # rays that meet none of the content
    assert 0.2 < empty.mean() < 0.9 and np.all(b.image[empty] == 0)
    rim = (a.image.max(axis=2) < 1e-6) & ~empty  # grazing rays: only B-spline tails of edge voxels
    assert b.to_uint8()[rim].max(initial=0) <= 2  # at most 2/255 in sRGB on black
    assert b.meta["segments"] <= 1.05 * a.meta["segments"]
    # without the content known (an interpolating model, or an older file) the haze is there
    thin.content_mask = None
    assert RayTracer(thin).render(cam, tolerance=1e-4).image[empty].max() > 1e-3


@pytest.mark.parametrize("wavelets", ["cubic", "linear", ["cubic", "cubic", "cubic", "haar"]])
def test_content_cells_are_where_a_non_zero_voxel_reaches(wavelets):
    rng = np.random.default_rng(2)
    data = np.zeros((10, 11, 12, 4), np.float32)
    data[rng.random((10, 11, 12)) < 0.01] = 1.0
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), wavelets, levels=1)
    origin, shape = np.array([-5, -3, -6]), np.array([20, 20, 24])
    cells = content_cells(wv, origin, shape)
    j0 = wv.groups[0].wavelet.order
    voxels = np.argwhere(wv.content_mask)
    expected = np.zeros(tuple(shape), bool)
    for g in wv.groups:  # voxel k's B-spline covers grid-0 fine cells [k + s, k + j + s), s = (j0 - j) / 2
        s, j = (j0 - g.wavelet.order) / 2, g.wavelet.order
        for k in voxels:
            lo = np.floor(k + s).astype(int) - origin
            hi = np.ceil(k + j + s).astype(int) - origin
            expected[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] = True
    assert np.array_equal(cells > 0, expected)


def test_repeated_one_shot_ray_traces_set_the_field_up_once(monkeypatch):
    wv = sparse_rgba("cubic", levels=1)
    cam = clwave.Camera(30, 20, size=8)
    first = clwave.raytrace(wv, cam, tolerance=1e-3)
    monkeypatch.setattr(RayTracer, "__init__", lambda *a, **k: (_ for _ in ()).throw(AssertionError("set up again")))
    again = clwave.raytrace(wv, cam, tolerance=1e-3)
    assert np.array_equal(first.image, again.image) and again.meta["setup_seconds"] == first.meta["setup_seconds"]


def test_bands_of_rows_give_the_image_of_one_launch(small_rgba, monkeypatch):
    from clwave.device import kernels

    wv, tracer = small_rgba
    cam = clwave.Camera(30, 20, size=(40, 24))
    monkeypatch.setattr(kernels, "LAUNCH_SECONDS", 1e9)  # the first band, then all the rest at once
    whole = tracer.render(cam, tolerance=1e-3).image
    monkeypatch.setattr(kernels, "LAUNCH_SECONDS", 0.0)  # a band of one work-group row each launch
    assert np.array_equal(tracer.render(cam, tolerance=1e-3).image, whole)


def test_ctrl_c_stops_a_long_ray_trace_within_a_second():
    """A 1024^2 trace at tolerance 1e-6 takes many seconds on a CPU; its launches are bands of rows (row_bands), so
    Ctrl-C, sent while one runs, stops it within a second of the signal."""
    script = f"""
import sys
import clwave
from clwave.raytrace import tracer as tracing
rgba = clwave.TransferFunction.preset("hydrogen").classify(clwave.phantom("hydrogen", 48))
wv = clwave.WaveletVolume.from_volume(rgba, "cubic", levels=2).threshold(keep=0.2)
tracer = clwave.RayTracer(wv)
tracer.render(clwave.Camera(30, 20, size=16), tolerance=1e-2)  # set-up and kernel build before the signal
{LAUNCHED.format(module="tracing", bands="row_bands")}
tracing.row_bands = launched
try:
    tracer.render(clwave.Camera(30, 20, size=1024), tolerance=1e-6)  # many seconds on a CPU
except KeyboardInterrupt:
    print("stopped", file=sys.stderr, flush=True)
    raise
print("finished", flush=True)
"""
    seconds, _, out, err = interrupted(script, b"stopped")
    assert seconds < 1.0 and b"finished" not in out and b"KeyboardInterrupt" in err


def test_coarse_lattices_stay_within_tolerance_of_float64():
    """At the coarsest detail the march skips on the region holding a segment's start, consumes for a marched segment
    the bound of every block it crosses, and ends it before a block of bound 0 (docs/raytracing.md §4): the shaded
    image within the tolerance of a float64 render of the same model and detail (running on into those blocks made it
    1.4e-2 off at 1e-2), with rays ended early on the way."""
    wv = clwave.WaveletVolume.from_volume(classified_ball(n=32), "cubic", levels=2).threshold(keep=0.05)
    tr = clwave.RayTracer(wv, lod=True)
    cam = clwave.Camera(31, 23, size=24)
    exact = tr.render(cam, tolerance=1e-6, precision="double", detail=2).image
    for tol in (1e-2, 1e-3):
        res = tr.render(cam, tolerance=tol, detail=2)
        assert res.meta["segments_by_lattice"]["4"] == res.meta["segments"] > 0
        assert res.meta["rays_terminated_early"] > 0
        assert np.max(np.abs(res.image - exact)) <= tol


def test_an_image_no_ray_drew_warns_saying_why():
    """trial26 finding 4: a ray-traced image of nothing ("0 segments": an all-black picture) ended with exit 0 and no
    word.  A render in which no ray met the model's content warns in one line naming the causes (the camera looking
    past it, a clip, a needle of a box, the tolerance); a render that drew something does not."""
    import warnings

    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", 16), levels=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error", clwave.ClwaveWarning)
        seen = clwave.raytrace(wv, clwave.Camera(size=12), shading=False, absorption=False, tolerance=1e-2)
    assert seen.meta["segments"] > 0
    with pytest.warns(clwave.ClwaveWarning, match=r"no ray met the model's content \(0 segments\).*camera") as caught:
        past = clwave.raytrace(wv, clwave.Camera(size=12, target=(500.0, 0.0, 0.0), extent=10.0), shading=False,
                               absorption=False, tolerance=1e-2)
    assert past.meta["segments"] == 0 and not past.image.any() and "\n" not in str(caught[0].message)
