"""The pixel filter of footprints narrower than a pixel (docs/splatting.md §1 "Pixel filter"): images keep the
model's mass, and a pixel is the mean of the exact line integrals over its square."""

import warnings

import numpy as np
import pytest

import clwave
from clwave.model.geometry import view_frame
from clwave.splat.reference import exact_xray
from clwave.splat.textures import FILTER_BELOW, footprints, pixel_filter


def model_integral(wv) -> float:
    """The model's volume integral in closed form: each scaling function of level L integrates to 2^(3L/2) times the
    voxel volume (a B-spline's integral is 1), each wavelet to 0."""
    g = wv.groups[0]
    (band, dense), = [(b, d) for b, d in zip(g.bands, g.dense_bands()) if b.key == "aaa"]
    return float(dense.sum()) * 2.0 ** (1.5 * band.level) * float(np.prod(wv.spacing))


def framed(vol, angles, size, wider=1.6):
    """An orthographic camera whose image holds the B-splines' tails past the voxels."""
    return clwave.Camera(*angles, size=size, extent=clwave.Camera(*angles, size=size).view(vol).pixel * size * wider)


@pytest.mark.parametrize("r", [1.0, 3.0, 4.0, 7.5])
def test_pixel_filter_is_the_box_mean_of_the_interpolant(r):
    """Against a dense midpoint rule of the samples' linear interpolant (zeros beyond, as the kernels read it)."""
    data = np.random.default_rng(3).random((3, 9))
    out, centre = pixel_filter(data, 4.0, r, axis=1)
    grow = centre - 4.0
    x = np.arange(out.shape[1]) - grow  # the filtered samples' positions in the input's texels
    k = 4000
    t = x[:, None] + (np.arange(k) + 0.5) / k * r - r / 2  # midpoints across each box
    for row in range(3):
        line = np.interp(t, np.arange(-1, 10), np.concatenate([[0.0], data[row], [0.0]]), left=0.0, right=0.0)
        assert np.allclose(out[row], line.mean(axis=1), atol=1e-6)
    assert out.shape == (3, 9 + 2 * int(grow))


@pytest.mark.parametrize("P", [2, 5, 16])
def test_filtered_samples_p_apart_sum_to_the_texture_sum(P):
    """Whatever its phase, a row of pixels (samples P apart) sums the unfiltered samples over P: a splat keeps its
    mass at any sub-texel position too (the bilinear weights mix two such sums)."""
    data = np.random.default_rng(4).random((2, 11))
    out, _ = pixel_filter(data, 5.0, float(P), axis=1)
    for phase in range(P):
        assert np.allclose(out[:, phase::P].sum(axis=1), data.sum(axis=1) / P, rtol=1e-12)


def test_only_footprints_narrower_than_the_pixel_are_filtered():
    n, u, v = view_frame(30.0, 20.0)
    bands = [(0, "aaa"), (2, "aaa")]  # voxels 1.37 and 5.46 wide along u, 1.41 and 5.63 along v
    plain = footprints("cubic", (1, 1, 1), n, u, v, bands, texel=0.25)
    pixel = 3.0 / FILTER_BELOW
    assert 1.41 < FILTER_BELOW * pixel < 4 * 1.36
    filtered = footprints("cubic", (1, 1, 1), n, u, v, bands, texel=0.25, pixel=pixel)
    assert np.array_equal(filtered[(2, "aaa")].data, plain[(2, "aaa")].data)
    small, wide = plain[(0, "aaa")], filtered[(0, "aaa")]
    assert wide.data.shape[0] == small.data.shape[0] + 38 and wide.data.shape[1] == small.data.shape[1] + 38
    mass = [float(t.data.astype(float).sum()) * t.h_u * t.h_v for t in (small, wide)]
    assert mass[1] == pytest.approx(mass[0], rel=1e-6) and mass[0] == pytest.approx(1.0, rel=1e-4)


# fuzz29's needle is (10, 15, 14) voxels of (171, 1.2, 1) (docs/known-gaps.md §15; its textures take minutes): this
# one is 400 x 18 x 14, its splats a twentieth to a fifth of a pixel wide across
NEEDLE = dict(shape=(10, 15, 14), spacing=(40, 1.2, 1))


# the coarse level's voxels are 1 to 4 pixels long along v, point-sampled: linear ones alias by up to 5e-3 of theirs
# (Haar's point samples of such boxes and its spatial textures' jumps err more: docs/known-gaps.md §15)
@pytest.mark.parametrize("family, tol", [("cubic", 5e-3), ("linear", 5e-3)])
@pytest.mark.parametrize("size", [16, 32, 64])
def test_needle_keeps_its_mass(cc, family, tol, size):
    """Once blank or nearly (fuzz29's needle: image maximum 0 at 16 and 32 pixels, 2e-4 at 64 against 11.3 at 128)."""
    vol = clwave.Volume(np.ones(NEEDLE["shape"], np.float32), spacing=NEEDLE["spacing"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", clwave.ClwaveWarning)  # the needle warning
        wv = clwave.WaveletVolume.from_volume(vol, family, levels=1)
        cam = framed(vol, (30, 20), size)
        pixel = cam.view(vol).pixel
        image = clwave.splat(wv, cam, device=cc).image
    assert float(image.sum()) * pixel ** 2 == pytest.approx(model_integral(wv), rel=tol)


@pytest.mark.parametrize("family", ["cubic", "linear"])
@pytest.mark.parametrize("angles, size", [((30, 20), 4), ((30, 20), 5), ((0, 0), 6)])
def test_small_image_of_a_big_volume_keeps_its_mass(cc, family, angles, size):
    """Every level's voxels under a third of a pixel (at 8 pixels, (30, 20), the coarsest level's are half a pixel,
    point-sampled: 2.9 % too much, docs/known-gaps.md §15)."""
    vol = clwave.Volume(np.random.default_rng(5).random((32, 32, 32)).astype(np.float32))
    wv = clwave.WaveletVolume.from_volume(vol, family, levels=2)
    cam = framed(vol, angles, size)
    image = clwave.splat(wv, cam, device=cc).image
    assert float(image.sum()) * cam.view(vol).pixel ** 2 == pytest.approx(model_integral(wv), rel=2e-3)


@pytest.mark.parametrize("family", ["cubic", "linear"])
@pytest.mark.parametrize("angles", [(30, 20), (-70, -15)])
def test_sub_pixel_footprints_give_pixel_means_of_the_exact_line_integrals(cc, family, angles):
    """Every footprint narrower than a pixel (one level, pixels of 8 voxels): each pixel is the mean of the exact
    line integrals over its square (12 x 12 of them a pixel, midpoint rule, against the image's maximum)."""
    vol = clwave.Volume(np.random.default_rng(6).random((16, 16, 16)).astype(np.float32))
    wv = clwave.WaveletVolume.from_volume(vol, family, levels=0)
    cam = clwave.Camera(*angles, size=5, extent=40.0)
    view = cam.view(vol)
    image = clwave.splat(wv, cam, device=cc).image[..., 0]
    k = 12
    fine = exact_xray(wv.reconstruct().data, wv.groups[0].wavelet.order, vol.spacing, vol.origin,
                      clwave.Camera(*angles, size=5 * k, extent=40.0).view(vol))[..., 0]
    means = fine.reshape(5, k, 5, k).mean(axis=(1, 3))
    assert view.pixel == 8.0
    assert np.abs(image - means).max() <= 2e-3 * np.abs(means).max()


def _cone(size, pixel, dso, angles, k=1):
    """A cone beam (magnification 1.5 at the isocentre), or its detector k times finer."""
    return clwave.ConeBeam(dso, 1.5 * dso, size * k, pixel=pixel / k, azimuth=angles[0], elevation=angles[1])


# a 32^3 model's voxels at 1/12 of a detector pixel (256^3 at 32^2), its depths 0.85 to 1.15 of the middle one's, whose
# pixel filters them (docs/splatting.md §1): measured 2.3e-2 and 2.2e-2, mass 1.8e-3 and 3.5e-3 (cubic, linear); an
# edge-on slab at dso 1000 (depths within 1.2 %), both axes filtered: 1.6e-4 and 7e-5, mass 4e-5 (at dso 100, 1.4e-2)
@pytest.mark.parametrize("family", ["cubic", "linear"])
@pytest.mark.parametrize("data, spacing, size, pixel, dso, angles, tol, mass", [
    (np.random.default_rng(7).random((32, 32, 32)), (1, 1, 1), 4, 20.0, 200.0, (30, 20), 2.5e-2, 5e-3),
    (np.ones((4, 24, 24)), (0.5, 1, 1), 6, 12.0, 1000.0, (0, 0), 5e-4, 1e-4),
])
def test_cone_beam_sub_pixel_footprints_give_pixel_means(cc, family, data, spacing, size, pixel, dso, angles, tol,
                                                         mass):
    """Once blank (the slab) or 19-26 % off (the fine model): each detector pixel is the mean of the exact cone-beam
    line integrals over its square (8 x 8 rays a pixel, midpoint rule, against the image's maximum)."""
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data.astype(np.float32), spacing=spacing), family, levels=1)
    image = clwave.splat(wv, _cone(size, pixel, dso, angles), device=cc).image[..., 0]
    k = 8
    fine = exact_xray(wv.reconstruct().data, wv.groups[0].wavelet.order, wv.spacing, wv.origin,
                      _cone(size, pixel, dso, angles, k).view(wv))[..., 0]
    means = fine.reshape(size, k, size, k).mean(axis=(1, 3))
    assert np.abs(image - means).max() <= tol * np.abs(means).max()
    assert float(image.sum()) == pytest.approx(float(means.sum()), rel=mass)
