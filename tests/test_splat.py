"""Wavelet splatting end to end: against exact line integrals of the same continuous model."""


import time

import numpy as np
import pytest

import clwave
from clwave.errors import DeviceMemoryError, InputError
from clwave.device.constants import record_uint4s
from clwave.splat import coarse as coarse_module
from clwave.splat import stages
from clwave.splat.reference import exact_xray


VIEWS = [((30, 20), (1.0, 1.0, 1.0)), ((0, 0), (1.0, 1.0, 1.0)), ((-70, -15), (2.0, 1.0, 0.5))]


@pytest.fixture(scope="module")
def data():
    return np.random.default_rng(7).random((16, 16, 16)).astype(np.float32)


# one image axis along a world axis: u (azimuth a multiple of 90 deg) or v (elevation 0); there Haar
# footprints jump along image columns or rows, linear ones have kinks
MIXED_VIEWS = [(angles, spacing) for angles in ((0, 10), (90, 25), (30, 0))
               for spacing in ((1.0, 1.0, 1.0), (2.0, 1.0, 0.5))]
CASES = [(family, tol, angles, spacing) for family, tol in (("quintic", 2e-3), ("cubic", 5e-3), ("linear", 2e-2),
                                                             ("haar", 2e-2))
         for angles, spacing in VIEWS + (MIXED_VIEWS if family in ("linear", "haar") else [])]


@pytest.mark.parametrize("family, tol, angles, spacing", CASES)
def test_full_set_equals_exact_line_integrals(cc, data, family, tol, angles, spacing):
    vol = clwave.Volume(data, spacing=spacing)
    wv = clwave.WaveletVolume.from_volume(vol, family, levels=2)
    cam = clwave.Camera(*angles, size=32)
    result = clwave.splat(wv, cam, device=cc)
    exact = exact_xray(wv.reconstruct().data, wv.groups[0].wavelet.order, vol.spacing, vol.origin,
                           cam.view(vol))
    assert result.image.shape == (32, 32, 1)
    assert np.abs(result.image - exact).max() <= tol * np.abs(exact).max()
    assert result.meta["coefficients"] == wv.kept and result.meta["texture_sampling"]


@pytest.mark.parametrize("angles", [a for a, _ in VIEWS])
def test_quintic_smooth_volume_within_1e3_of_exact_line_integrals(cc, angles):
    """Order 6 on a smooth volume (hydrogen), every coefficient: within 1e-3 of the image maximum."""
    vol = clwave.phantom("hydrogen", 24)
    wv = clwave.WaveletVolume.from_volume(vol, "quintic", levels=2)
    cam = clwave.Camera(*angles, size=32)
    exact = exact_xray(wv.reconstruct().data, 6, vol.spacing, vol.origin, cam.view(vol))
    assert np.abs(clwave.splat(wv, cam, device=cc).image - exact).max() <= 1e-3 * np.abs(exact).max()


def test_box_of_ones_integrates_to_its_length(cc):
    vol = clwave.Volume(np.ones((12, 10, 8), np.float32))  # 8 voxels along x
    wv = clwave.WaveletVolume.from_volume(vol, "cubic", levels=1)
    image = clwave.splat(wv, clwave.Camera(0, 0, size=32, extent=16.0), device=cc).image[..., 0]
    interior = image[12:20, 13:19]  # rays through the middle of the 10 x 12 face, away from its edges
    assert np.allclose(interior, 8.0, rtol=2e-3)
    line = clwave.splat(wv, clwave.Camera(90, 0, size=32, extent=16.0), device=cc).image[12:20, 13:19, 0]
    assert np.allclose(line, 10.0, rtol=2e-3)  # along y: 10 voxels


PIXEL = 1.1 * 233 / 256  # about a voxel (1.0012): pixel centres walk slowly across the voxel faces


@pytest.mark.parametrize("family", ["haar", "linear"])
@pytest.mark.parametrize("angles, shape, size, length", [
    ((0, 10), (12, 71, 12), (24, 80), 12 / np.cos(np.radians(10))),    # u = y: 71 voxel columns, through x
    ((90, 25), (12, 12, 71), (24, 80), 12 / np.cos(np.radians(25))),   # u = -x: 71 voxel columns, through y
    ((30, 0), (71, 40, 12), (80, 48), 12 / np.cos(np.radians(30)))])   # v = z: 71 voxel rows, through x
def test_box_of_ones_with_one_world_axis_in_the_image(cc, family, angles, shape, size, length):
    """A box of ones, pixels about a voxel wide, with pixel centres on voxel faces in the middle of
    the image: every pixel equals the exact line integral (the Haar footprint, a box along the
    world axis, once lost up to 98 % of it: jumps smeared inwards by bilinear lookup).  Interior
    pixels cross the box's x (or y) faces only: their line length is ``length``."""
    vol = clwave.Volume(np.ones(shape, np.float32))
    wv = clwave.WaveletVolume.from_volume(vol, family, levels=0)
    cam = clwave.Camera(*angles, size=size, extent=size[1] * PIXEL)
    result = clwave.splat(wv, cam, device=cc)
    image = result.image[..., 0]
    exact = exact_xray(wv.reconstruct().data, wv.groups[0].wavelet.order, vol.spacing, vol.origin,
                           cam.view(vol))[..., 0]
    interior = np.abs(exact - length) <= 1e-9 * length
    assert interior.sum() >= 200
    cells = "cells-u" if angles[0] % 90 == 0 else "cells-v"
    assert result.meta["texture_sampling"] == ([cells] if family == "haar" else ["spatial"])
    # Haar: exact along the cell axis, samples at 1/(8 P) pixel along the other; linear: bilinear
    # at 1/P pixel across kinks
    tol = 5e-4 if family == "haar" else 1e-3
    assert np.abs(image[interior] / length - 1).max() <= tol
    assert np.abs(image - exact).max() <= tol * length
    # mass: the pixel sum of the exact image; for linear that is the volume's integral, for Haar
    # it differs by the pixel grid's sampling of the box's jumps (pixel centres inside x pixel)
    mass = image.sum(dtype=np.float64) * PIXEL ** 2
    assert mass == pytest.approx(exact.sum() * PIXEL ** 2, rel=1e-4)
    if family == "linear":
        assert mass == pytest.approx(np.prod(shape), rel=1e-4)
    assert np.array_equal(clwave.splat(wv, cam, device=cc).image, result.image)  # bit-identical repeat


@pytest.mark.parametrize("levels", [0, 1, 2])
@pytest.mark.parametrize("angles, size", [((0, 0), 9), ((0, 0), 5), ((0, -90), 5), ((90, 0), (7, 9)),
                                          ((180, 0), 9)])
def test_haar_cells_count_a_pixel_on_a_voxel_face_once(cc, levels, angles, size):
    """A Haar box of ones at axis views whose pixel centres lie on voxel faces (odd sizes: the middle pixel at the
    content's centre, a face of the 8 voxels a side): each pixel inside the box's shadow is its chord, 8, as a
    closed form.  Each splat placed such a pixel by its own rounded centre, so that both voxels beside a face
    counted it (16 and 32: two and four cells) or neither (0; diff22's fuzzing)."""
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(np.ones((8, 8, 8), np.float32)), "haar", levels=levels)
    cam = clwave.Camera(*angles, size=size)
    result = clwave.splat(wv, cam, device=cc)
    assert result.meta["texture_sampling"] == ["cells"]
    view = cam.view(wv)
    across = np.abs(np.stack([view.pixel_centres() @ view.u, view.pixel_centres() @ view.v], -1))
    inside = np.all(across < 4 - 1e-9, axis=-1)  # strictly inside the 8 x 8 shadow; on its edge: 0 or 8
    image = result.image[..., 0]
    assert inside.sum() >= 9
    np.testing.assert_allclose(image[inside], 8.0, rtol=1e-6)
    assert np.all(np.isclose(image[~inside], 0.0, atol=1e-6) | np.isclose(image[~inside], 8.0, rtol=1e-6))


@pytest.mark.parametrize("family", ["cubic", "linear"])
def test_cubic_textures_are_trimmed_to_their_samples_above_the_tolerance(data, family):
    """Paper Fig. 9: a cubic texture's outer rows and columns each hold a sample above TEXTURE_TOL
    of its peak, and trimming removed samples; linear ones keep their whole support box."""
    from clwave.splat.textures import footprints
    from clwave.splat.tables import TEXTURE_TOL, ViewTables

    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), family, levels=2)
    view = clwave.Camera(30, 20, size=32).view(wv)
    tables = ViewTables(wv, 0, [(view, None)])
    for (m, key), tex in tables.textures.items():
        if tex is None:
            continue
        full = footprints(family, wv.spacing, view.n, view.u, view.v, [(m, key)], omega_s=tables.omega_s,
                          texel=tex.h_u)[(m, key)].data
        if family == "linear":
            assert tex.data.shape == full.shape
            continue
        assert tex.data.size < full.size
        for border in (tex.data[0], tex.data[-1], tex.data[:, 0], tex.data[:, -1]):
            assert np.abs(border).max() > TEXTURE_TOL * np.abs(tex.data).max()


def test_only_bands_with_coefficients_get_textures(cc, data):
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), "cubic", levels=2).threshold(keep=0.5)
    present = {(band.level, band.key) for band, index, _ in wv.bands(0) if len(index)}
    assert 1 < len(present) < len(wv.groups[0].bands)  # the threshold emptied some bands
    acc = clwave.SplatRenderer(wv, device=cc).begin(clwave.Camera(30, 20, size=32))
    assert set(acc.tables[0].textures) == present


def test_rgba_channels_share_footprints_and_repeat_bit_identically(cc, data):
    rgba = np.stack([data, 2 * data, data ** 2, 0.5 * data], -1)
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(rgba), "cubic", levels=2).threshold(keep=0.2)
    cam = clwave.Camera(25, 35, size=(24, 40))
    renderer = clwave.SplatRenderer(wv, device=cc)
    first = clwave.splat(wv, cam, renderer=renderer).image
    again = clwave.splat(wv, cam, renderer=renderer).image
    assert first.shape == (24, 40, 4) and np.array_equal(first, again)
    assert np.allclose(first[..., 1], 2 * first[..., 0], rtol=1e-5, atol=1e-5)  # linear in the coefficients


def test_splitting_the_tile_lists_gives_the_same_image(cc, data, monkeypatch):
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), "cubic", levels=2)
    cam = clwave.Camera(30, 20, size=32)
    whole = clwave.splat(wv, cam, device=cc)
    # room for about 2000 pairs (scalar records) at once
    monkeypatch.setattr(stages, "TILE_LIST_SHARE", 2000 * 16 * record_uint4s(1) / cc.info.global_mem)
    split = clwave.splat(wv, cam, device=cc)
    assert np.allclose(split.image, whole.image, rtol=1e-5, atol=1e-5)


def test_framebuffer_too_large_for_the_device(cc, data):
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), "haar", levels=1)
    side = int(np.sqrt(cc.info.max_alloc / 16)) + 16
    with pytest.raises(DeviceMemoryError, match=r"framebuffer of a \d+x\d+ image needs .* allows .* whatever the "
                                                r"device memory given; render a smaller image"):
        clwave.splat(wv, clwave.Camera(0, 0, size=side), device=cc)


def test_progressive_frames_refine_to_the_one_shot_image(cc, data):
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), "cubic", levels=2).threshold(keep=0.5)
    cam = clwave.Camera(30, 20, size=32)
    renderer = clwave.SplatRenderer(wv, device=cc)
    frames = list(clwave.progressive(wv, cam, steps=5, renderer=renderer))
    one_shot = clwave.splat(wv, cam, renderer=renderer).image
    assert len(frames) == 5 and frames[-1].coefficients == wv.kept and frames[-1].fraction == 1.0
    assert np.allclose(frames[-1].image, one_shot, rtol=1e-5, atol=1e-5)
    counts = [f.coefficients for f in frames]
    assert counts == sorted(counts) and counts[0] < counts[-1]
    energies = [f.energy for f in frames]
    assert np.all(np.diff(energies) >= 0) and energies[-1] == pytest.approx(1.0)
    assert frames[-1].rms_error == 0 and frames[0].rms_error > frames[2].rms_error
    assert frames[0].max_error >= frames[0].rms_error > 0
    assert np.allclose(frames[1].error_image(), frames[-1].image - frames[1].image)


@pytest.mark.parametrize("volume", ["hydrogen", "random"])
def test_progressive_error_falls_by_a_fifth_at_every_doubling(cc, volume):
    """Frames add coefficients by importance across all bands, so every doubling of the coefficients
    takes at least 20 % off the RMS error against the final image (the first frames do not stall
    on the approximation band)."""
    vol = clwave.phantom("hydrogen", 64) if volume == "hydrogen" else \
        clwave.Volume(np.random.default_rng(3).random((48, 48, 48)).astype(np.float32))
    wv = clwave.WaveletVolume.from_volume(vol, "cubic", levels=3).threshold(keep=0.05)
    frames = list(clwave.progressive(wv, clwave.Camera(30, 20, size=96), steps=6, device=cc))
    errors = [f.relative_rms_error for f in frames]
    assert errors[-1] == 0 and all(later <= 0.8 * earlier for earlier, later in zip(errors, errors[1:]))
    final = frames[-1].final_image()
    assert frames[0].relative_max_error == pytest.approx(frames[0].max_error / np.abs(final).max())
    assert [f.voxel_fraction for f in frames] == [f.coefficients / vol.data.size for f in frames]
    assert frames[-1].voxel_fraction == round(0.05 * vol.data.size) / vol.data.size


def test_a_progressive_frame_saves_like_a_render(cc, data, tmp_path):
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), "cubic", levels=2).threshold(keep=0.3)
    frame = next(iter(clwave.progressive(wv, clwave.Camera(30, 20, size=16), steps=3, device=cc)))
    frame.save(tmp_path / "f.npy")
    frame.save(tmp_path / "f.png")
    assert np.array_equal(np.load(tmp_path / "f.npy"), frame.image) and (tmp_path / "f.png").stat().st_size > 0
    with pytest.raises(clwave.OutputExistsError):
        frame.save(tmp_path / "f.npy")


def test_progressive_budget_returns_completed_frames(cc, data):
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), "cubic", levels=2)
    frames = list(clwave.progressive(wv, clwave.Camera(30, 20, size=32), budget=1e-6, device=cc))
    assert len(frames) == 1 and 0 < frames[0].coefficients < wv.kept
    assert frames[0].rms_error > 0  # compared with the full image, rendered on demand


def test_progressive_budget_does_not_count_the_set_up_as_splatting(cc, data, monkeypatch):
    # the time to the first frame (the renderer's set-up, the view's) was counted as per-coefficient cost: a budget
    # of set-up plus far more than the frames' own time gave one frame (trial16)
    from clwave.splat.renderer import SplatRenderer

    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), "cubic", levels=2)
    renderer, cam = clwave.SplatRenderer(wv, device=cc), clwave.Camera(30, 20, size=32)
    start = time.perf_counter()
    assert len(list(clwave.progressive(wv, cam, steps=8, renderer=renderer))) == 8
    frames_alone = time.perf_counter() - start
    begin = SplatRenderer.begin
    monkeypatch.setattr(SplatRenderer, "begin", lambda *a, **k: (time.sleep(2.0), begin(*a, **k))[1])
    frames = list(clwave.progressive(wv, cam, budget=2.0 + 4 * frames_alone + 1.0, renderer=renderer))
    assert len(frames) == 8 and frames[-1].coefficients == wv.kept


def test_scaling_functions_only_and_local_detail(cc, data):
    vol = clwave.Volume(data)
    part = clwave.WaveletVolume.from_volume(vol, "cubic", levels=0).threshold(keep=0.3)  # paper Fig. 17
    cam = clwave.Camera(30, 20, size=32)
    image = clwave.splat(part, cam, device=cc).image
    exact = exact_xray(part.reconstruct().data, 4, vol.spacing, vol.origin, cam.view(vol))
    assert np.abs(image - exact).max() <= 5e-3 * np.abs(exact).max()


@pytest.mark.parametrize("bad", [dict(steps=0), dict(steps=2.5), dict(steps="two"), dict(steps=float("nan")),
                                 dict(budget=0), dict(budget=-1.0), dict(steps=2, budget=1.0), dict()])
def test_bad_progressive_arguments(cc, data, bad):
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), "haar", levels=1)
    with pytest.raises(InputError) as err:
        clwave.progressive(wv, clwave.Camera(0, 0, 8), device=cc, **bad)
    assert "\n" not in str(err.value)


def test_splat_needs_a_wavelet_volume_and_a_camera(cc, data):
    with pytest.raises(InputError):
        clwave.splat(data, clwave.Camera(0, 0, 8), device=cc)
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), "haar", levels=1)
    with pytest.raises(InputError):
        clwave.splat(wv, "front", device=cc)


@pytest.mark.parametrize("tolerance", [2e-2, 1e-2])
@pytest.mark.parametrize("volume", ["random", "shepp-logan"])
@pytest.mark.parametrize("wavelet", ["cubic", "quintic"])
def test_coarse_framebuffers_stay_within_their_tolerance(cc, data, tolerance, volume, wavelet):
    vol = clwave.Volume(data) if volume == "random" else clwave.phantom("shepp-logan", n=32)
    wv = clwave.WaveletVolume.from_volume(vol, wavelet, levels=3)
    single = clwave.SplatRenderer(wv, device=cc)
    coarse = clwave.SplatRenderer(wv, device=cc, coarse=tolerance)
    for angles in ((30, 20), (0, 0), (-70, -15)):
        cam = clwave.Camera(*angles, size=2 * vol.shape[0])
        want, got = clwave.splat(wv, cam, renderer=single), clwave.splat(wv, cam, renderer=coarse)
        assert want.meta["framebuffers"] == [1] and got.meta["framebuffers"][-1] > 1
        error = np.abs(got.image - want.image).max()
        assert 0 < error <= tolerance * np.abs(want.image).max()  # coarse bands drawn, within the tolerance


def test_coarse_framebuffers_hold_a_sharp_volume_at_a_small_tolerance(cc):
    # Shepp-Logan's edges at pixels of 0.35 voxel and coarse=1e-3 (clwave render's 8-bit default): the rule before
    # (COARSE_REFERENCE measured at 1e-2 and scaled by the fourth power) drew framebuffers 1, 2, 4 and erred by
    # 1.14e-3 of the image maximum at (30, 20)
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("shepp-logan", n=32), "cubic", levels=3)
    single = clwave.SplatRenderer(wv, device=cc)
    coarse = clwave.SplatRenderer(wv, device=cc, coarse=1e-3)
    for angles in ((30, 20), (0, 0), (-70, -15)):
        cam = clwave.Camera(*angles, size=128)
        want, got = single.render(cam), coarse.render(cam)
        assert max(got.meta["framebuffers"]) > 1
        assert np.abs(got.image - want.image).max() <= 1e-3 * np.abs(want.image).max()


def test_coarse_framebuffers_only_for_cubic_and_checked(cc, data):
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), "linear", levels=3)
    cam = clwave.Camera(30, 20, size=32)
    assert clwave.splat(wv, cam, device=cc, coarse=0.5 - 1e-9).meta["framebuffers"] == [1]
    for bad in (0, 1.0, -1e-2, float("nan"), "1e-2"):
        with pytest.raises(InputError, match="coarse") as err:
            clwave.SplatRenderer(wv, device=cc, coarse=bad)
        assert "\n" not in str(err.value)


def test_upsampling_is_the_prefiltered_cubic_bspline():
    from scipy.ndimage import map_coordinates, spline_filter

    samples = np.random.default_rng(2).random((64, 64)).astype(np.float32)
    for shape, (fu, fv) in (((64, 61), (2, 2)), ((61, 64), (4, 4)), ((61, 64), (2, 8))):
        coarse = [-(-n // f) + 2 * coarse_module.COARSE_MARGIN for n, f in zip(shape, (fv, fu))]
        # fine pixel centres as coarse indices
        at = [(np.arange(n) + 0.5 - n / 2) / f + c / 2 - 0.5 for n, c, f in zip(shape, coarse, (fv, fu))]
        assert all(a.min() > 4 and a.max() < c - 5 for a, c in zip(at, coarse))  # the ends play no part
        grid = samples[: coarse[0], : coarse[1]]
        want = map_coordinates(spline_filter(grid.astype(float), mode="mirror"), np.meshgrid(*at, indexing="ij"),
                               order=3, prefilter=False, mode="mirror")
        got = coarse_module.upsample(grid, shape, (fu, fv))
        assert got.shape == shape and np.allclose(got, want, rtol=1e-6, atol=1e-6)


def test_one_shot_calls_share_their_renderer_until_released(cc, data, monkeypatch):
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), "cubic", levels=2).threshold(keep=0.3)
    cams = [clwave.Camera(30, 20, size=24), clwave.Camera(-50, 10, size=24)]
    first = [clwave.splat(wv, cam, device=cc).image for cam in cams]
    frames = list(clwave.progressive(wv, cams[0], steps=2, device=cc))

    def no_new_renderer(*args, **kwargs):
        raise AssertionError("a one-shot call built a second renderer")

    monkeypatch.setattr(clwave.SplatRenderer, "__init__", no_new_renderer)
    again = [clwave.splat(wv, cam, device=cc).image for cam in cams]  # the same renderer, no new set-up
    assert all(np.array_equal(a, b) for a, b in zip(first, again))
    assert np.allclose(frames[-1].image, first[0], rtol=1e-5, atol=1e-6)  # two chunks: another sum order
    with pytest.raises(AssertionError, match="second renderer"):  # other options: another renderer
        clwave.splat(wv, cams[0], device=cc, coarse=1e-2)
    wv.release()
    with pytest.raises(AssertionError, match="second renderer"):
        clwave.splat(wv, cams[0], device=cc)


def test_bounded_launches_give_the_image_of_long_ones(cc, data, monkeypatch):
    """Binning and accumulation go in launches of about LAUNCH_SECONDS (Ctrl-C is taken between them,
    docs/splatting.md §6): a band of one splat of every chunk, or one tile, a launch gives the image of
    long launches bit for bit."""
    from clwave.device import kernels

    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), "cubic", levels=2).threshold(keep=0.5)
    cam = clwave.Camera(30, 20, size=(40, 56))
    monkeypatch.setattr(kernels, "LAUNCH_SECONDS", 1e9)
    whole = clwave.splat(wv, cam, renderer=clwave.SplatRenderer(wv, device=cc)).image
    monkeypatch.setattr(kernels, "LAUNCH_SECONDS", 0.0)
    banded = clwave.splat(wv, cam, renderer=clwave.SplatRenderer(wv, device=cc)).image
    assert np.abs(whole).max() > 1 and np.array_equal(banded, whole)


MAGNIFIED = [(family, tol, angles, spacing) for family, tol in (("cubic", 1e-3), ("linear", 2e-3), ("haar", 1e-2))
             for angles, spacing in (VIEWS[0], VIEWS[2], ((0, 10), (2.0, 1.0, 0.5)))] + [("quintic", 1e-3, (30, 20),
                                                                                              (1.0, 1.0, 1.0))]


@pytest.mark.parametrize("family, tol, angles, spacing", MAGNIFIED)
def test_magnified_views_equal_exact_line_integrals_from_textures_that_do_not_grow(cc, data, family, tol, angles,
                                                                                    spacing):
    """Pixels of 1/128 and 1/512 of the finest voxel spacing (docs/splatting.md §2): the textures stop at the band's
    texel, the same at both, read by per-pixel interpolation, and the image stays within the tolerances of the
    full-set views from the exact line integrals."""
    from clwave.splat.tables import GATHER_U, ViewTables

    vol = clwave.Volume(data, spacing=spacing)
    wv = clwave.WaveletVolume.from_volume(vol, family, levels=2)
    pools = []
    for extent in (0.25, 0.0625):
        cam = clwave.Camera(*angles, size=32, extent=extent * min(spacing))
        tables = ViewTables(wv, 0, [(cam.view(wv), None)])
        assert any(lookup & GATHER_U for lookup in tables.tex_int[:, 3]) or family == "haar"
        pools.append(tables.texels.size)
        exact = exact_xray(wv.reconstruct().data, wv.groups[0].wavelet.order, vol.spacing, vol.origin, cam.view(vol))
        assert np.abs(clwave.splat(wv, cam, device=cc).image - exact).max() <= tol * np.abs(exact).max()
    if "cells" in tables.samplings[0]:  # Haar cells' sampled axis: 8 s texels a pixel, rounded up where s < 2 <= 8 s
        assert pools[1] <= 1.5 * pools[0]
    else:
        assert pools[0] == pools[1]


@pytest.mark.parametrize("kind", [float, lambda s: np.int64(s) if isinstance(s, int) else np.float64(s)],
                         ids=["float", "numpy"])
def test_the_texture_lookup_follows_the_texels_per_pixel_by_value(cc, data, monkeypatch, kind):
    """A band's texels per pixel set its lookup by value (phase planes from 2, gathered per pixel below it, in a
    magnified view), not by type: the same numbers as another type give the same tables and images bit for bit."""
    from clwave.splat import tables

    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), "linear", levels=2)
    cameras = [clwave.Camera(30, 20, size=32), clwave.Camera(30, 20, size=32, extent=0.25)]

    def drawn(cam):
        t = tables.ViewTables(wv, 0, [(cam.view(wv), None)])
        return t.tex_int, t.texels, clwave.splat(wv, cam, device=cc).image

    expect = [drawn(cam) for cam in cameras]
    assert [{lookup & (tables.LINEAR_U | tables.GATHER_U) for lookup in ints[:, 3]} for ints, _, _ in expect] == [
        {tables.LINEAR_U}, {tables.GATHER_U}]  # both modes
    per_pixel = tables.texels_per_pixel
    monkeypatch.setattr(tables, "texels_per_pixel", lambda *a, **k: kind(per_pixel(*a, **k)))
    for cam, want in zip(cameras, expect):
        assert all(np.array_equal(got, w) for got, w in zip(drawn(cam), want))


def test_more_progressive_steps_than_the_model_allows_are_told():
    """Each splatting frame doubles the coefficients from one, so a model of N allows about log2(N) + 1 frames:
    steps=40 gave 13 frames silently (trial21; ray tracing warned of its own limit already)."""
    from clwave.errors import ClwaveWarning

    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", 16), levels=1).threshold(keep=0.6)
    camera = clwave.Camera(30, 20, size=16)
    with pytest.warns(ClwaveWarning, match=r"a model of 2,458 coefficients allows 13 progressive frames, each "
                                           r"doubling them, not steps=40"):
        assert len(list(clwave.progressive(wv, camera, steps=40))) == 13
