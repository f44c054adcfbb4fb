"""Camera conventions (docs/coordinates.md §2) and bad views."""

import warnings
from itertools import product

import numpy as np
import pytest

from clwave.model.camera import MAX_PIXELS_ACROSS, Camera
from clwave.errors import InputError
from clwave.model.volume import Volume


@pytest.mark.parametrize("az, el", [(0, 0), (30, 20), (-70, -15), (90, 0), (0, 90), (123.4, -56.7)])
def test_basis_is_right_handed_and_orthonormal(az, el):
    n, u, v = Camera(az, el, 8).basis()
    assert np.allclose(np.stack([n, u, v]) @ np.stack([n, u, v]).T, np.eye(3), atol=1e-15)
    assert np.allclose(np.cross(u, v), n, atol=1e-15)


def test_axis_view_is_not_mirrored():
    # camera on +x looking along -x: image right is +y, image up is +z
    n, u, v = Camera(0, 0, 8).basis()
    assert n.tolist() == [1, 0, 0] and u.tolist() == [0, 1, 0] and v.tolist() == [0, 0, 1]


def test_pixel_centres_and_default_extent():
    vol = Volume(np.zeros((4, 6, 8)), spacing=(3.0, 2.0, 1.0), origin=(1.0, 2.0, 3.0))
    view = Camera(0, 0, (10, 20)).view(vol)
    diameter = np.sqrt(8 ** 2 + 12 ** 2 + 12 ** 2)  # an empty volume: the sphere around its voxel box
    assert view.pixel == pytest.approx(diameter / 10)  # fills the shorter side, 10 pixels
    centres = view.pixel_centres()
    assert centres.shape == (10, 20, 3)
    # top-left pixel centre: target + (0.5 - W/2) p u + (H/2 - 0.5) p v
    expected = np.array([1.0, 2.0, 3.0]) + (0.5 - 10) * view.pixel * view.u + (5 - 0.5) * view.pixel * view.v
    assert np.allclose(centres[0, 0], expected)
    assert np.allclose(view.to_pixels(centres.reshape(-1, 3)).reshape(10, 20, 2)[3, 7], [7, 3])


@pytest.mark.parametrize("kwargs", [dict(azimuth=float("nan")), dict(elevation=float("inf")), dict(size=0),
                                    dict(size=(-3, 4)), dict(size=2.5), dict(size="big"), dict(extent=0),
                                    dict(target=(0, 0)), dict(fov=180), dict(fit="cube"),
                                    dict(fit="box", extent=3.0), dict(fit="box", perspective=True, distance=9.0)])
def test_bad_views_are_one_line_errors(kwargs):
    with pytest.raises(InputError) as err:
        Camera(**kwargs)
    assert "\n" not in str(err.value)


def test_default_view_frames_the_non_empty_region_at_every_azimuth():
    data = np.zeros((32, 40, 48), np.float32)
    data[4:12, 20:30, 2:10] = 1.0  # content in a corner: x 2..9, y 20..29, z 4..11 (voxel indices)
    vol = Volume(data, spacing=(1.0, 2.0, 0.5), origin=(5.0, -3.0, 1.0))
    lo, hi = vol.content_box()
    corners = vol.voxel_to_world(np.array([[3.5, 19.5, 1.5], [11.5, 29.5, 9.5]]))  # voxel faces
    assert np.allclose(lo, corners.min(axis=0)) and np.allclose(hi, corners.max(axis=0))
    diameter = np.linalg.norm(hi - lo)
    inside = vol.voxel_to_world(np.argwhere(data > 0))
    for az in (0, 33, 90, 200):
        view = Camera(az, 25, (60, 80)).view(vol)
        assert np.allclose(view.target, (lo + hi) / 2)
        assert view.pixel * 60 == pytest.approx(diameter)  # the bounding sphere across the shorter side
        px = view.to_pixels(inside)  # every non-empty voxel lands in the image
        assert px.min() >= -0.5 and px[:, 0].max() <= 79.5 and px[:, 1].max() <= 59.5
    # the model remembers the content of the volume it was made from, and so does its .clw file
    from clwave.model.wavelet import WaveletVolume
    wv = WaveletVolume.from_volume(vol, levels=1).threshold(keep=0.2)
    assert np.allclose(wv.content_box()[0], lo) and np.allclose(wv.content_box()[1], hi)
    assert Camera(33, 25, 64).view(wv).pixel == pytest.approx(Camera(33, 25, 64).view(vol).pixel)


@pytest.mark.parametrize("kwargs", [{}, dict(target=(1.0, -2.0, 0.5), extent=30.0),
                                    dict(perspective=True, fov=40.0), dict(perspective=True, distance=60.0)])
def test_a_reduced_camera_is_the_same_view_with_larger_pixels(kwargs):
    # as ConeBeam.reduced (tests/test_raytrace_cone.py): a progressive frame's reduced image has the same centre, and
    # its pixels are reduction x reduction of the full image's, also where the sides round up (42 x 37 -> 11 x 10)
    vol = Volume(np.zeros((6, 7, 8)), spacing=(1.0, 2.0, 1.5), origin=(0.5, 1.0, -1.0))
    points = np.random.default_rng(3).uniform(-5, 5, (20, 3))
    for size in ((40, 36), (42, 37)):
        cam = Camera(35, -25, size, **kwargs)
        small = cam.reduced(4, cam.view(vol))
        (H, W), (h, w) = cam.size, small.size
        assert (h, w) == (-(-H // 4), -(-W // 4)) and small.perspective == cam.perspective
        full = cam.view(vol).to_pixels(points) - (np.array([W, H]) / 2.0 - 0.5)  # from the image's centre
        np.testing.assert_allclose(small.view(vol).to_pixels(points) - (np.array([w, h]) / 2.0 - 0.5), full / 4,
                                   rtol=0, atol=1e-9)


@pytest.mark.parametrize("perspective", [False, True])
def test_a_box_fit_brings_the_content_box_to_the_image_edge(perspective):
    """fit="box": every corner of the content box projects inside the image (pixel centres -0.5 .. W - 0.5 are its
    edges), and the farthest touches an edge (1e-9 pixel), at any view and for either image side the longer; a
    slab 32 times longer than wide, seen from its side in a tall image, spans its height where its bounding
    sphere, across the width, spans an eighth of it."""
    data = np.zeros((8, 20, 12), np.float32)
    data[1:7, 3:19, 2:5] = 1.0
    vol = Volume(data, spacing=(1.0, 0.5, 2.0), origin=(1.0, -2.0, 3.0))
    corners = np.array(list(product(*zip(*vol.content_box()))))
    assert repr(Camera(0, 0, 8, fit="box")).endswith("fit='box')") and "fit" not in repr(Camera(0, 0, 8))
    for az, el, size in ((0, 0, (20, 30)), (33, 25, (30, 20)), (200, -60, 17), (90, 90, (8, 64))):
        view = Camera(az, el, size, fit="box", perspective=perspective).view(vol)
        (H, W), px = view.size, view.to_pixels(corners)
        assert px.min() >= -0.5 - 1e-9 and px[:, 0].max() <= W - 0.5 + 1e-9 and px[:, 1].max() <= H - 0.5 + 1e-9
        assert min(px.min() + 0.5, W - 0.5 - px[:, 0].max(), H - 0.5 - px[:, 1].max()) < 1e-9
    slab = Volume(np.ones((64, 2, 2), np.float32))  # z 64 voxels long, seen along x: z up the image
    rows = [np.ptp(Camera(0, 0, (512, 64), fit=fit).view(slab).to_pixels(
        np.array(list(product(*zip(*slab.content_box())))))[:, 1]) for fit in ("sphere", "box")]
    assert rows[1] == pytest.approx(512) and rows[0] == pytest.approx(64 * 64 / np.sqrt(64 ** 2 + 8))
    assert Camera(0, 0, 16, fit="sphere").view(vol).pixel == Camera(0, 0, 16).view(vol).pixel  # the default


def test_a_pixel_too_small_for_the_kernels_float32_steps_is_refused():
    # an extent of 1e-40 overflowed the splat kernels' float32 steps (a crash), a subnormal 1e-320 made a pixel of 0
    # (an internal error); the bound is the most pixels across the content box's diagonal
    volume = Volume(np.zeros((8, 8, 8), np.float32))
    diagonal = 8.0 * np.sqrt(3.0)  # the box of 8 unit voxels a side, to within a voxel: the factors below are 2
    for extent in (1e-40, 1e-320, 64 * diagonal / MAX_PIXELS_ACROSS / 2):
        with pytest.raises(InputError, match="too small for the volume"):
            Camera(size=64, extent=extent).view(volume)
    assert Camera(size=64, extent=64 * diagonal / MAX_PIXELS_ACROSS * 2).view(volume).pixel > 0
    with pytest.raises(InputError, match="distance=1e-300"):
        Camera(size=64, perspective=True, distance=1e-300).view(volume)


def test_a_needle_of_a_box_warns_naming_the_spacing(tmp_path, capsys):
    """trial26 finding 4: a spacing of axes in different units (5000 m/s against 0.0014 degrees, 3.6e6 : 1) made an
    all-black ray-traced image with exit 0, and 1000 : 5 : 5 a one-pixel line, with no hint.  A content box whose two
    shorter sides are both over 100 times shorter than its longest, which no view shows as more than a line or a dot,
    warns once, naming spacing= (--spacing on the command line); a slab (one short side, seen face on) and 100 : 1 do
    not."""
    from clwave.cli import main
    from clwave.errors import ClwaveWarning

    data = np.zeros((8, 8, 8), np.float32)
    data[2:6, 2:6, 2:6] = 1.0
    for spacing in ((5000, 0.0013888889, 0.0013888889), (1000, 5, 5), (1, 1, 101)):
        with pytest.warns(ClwaveWarning, match=r"times longer than .* spacing= in one unit") as caught:
            Camera().view(Volume(data, spacing=spacing))
        assert len(caught) == 1 and "\n" not in str(caught[0].message)
    for spacing in ((1, 1, 1), (100, 1, 1), (1, 200, 200), (0.01, 1, 1)):
        with warnings.catch_warnings():
            warnings.simplefilter("error", ClwaveWarning)
            Camera().view(Volume(data, spacing=spacing))
    np.save(tmp_path / "cube.npy", data)
    code = main(["render", str(tmp_path / "cube.npy"), "--spacing", "5000,0.0013888889,0.0013888889", "--method",
                 "raytrace", "--xray", "--turntable", "3", "--size", "16", "-o", str(tmp_path / "t.gif")])
    err = capsys.readouterr().err
    assert code == 0 and err.count("times longer than") == 1, err
    assert "--spacing in one unit" in err and "spacing=" not in err
