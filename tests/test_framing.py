"""What a view opens at and frames: a slab seen down its thin axis (camera.opening_view), the content of a noisy
volume rather than its box (noise.signal_box), by the command line's render and turntable alike."""

import json

import numpy as np
import pytest

import clwave
from clwave.cli import main
from clwave.model.camera import OPENING, SLAB_VIEWS, framed_box, opening_view
from clwave.model.geometry import view_frame

SIDE, THIN = 40, 6  # a slab 32 x 32 x 6 voxels in a 40^3 box


def slab(axis):
    data = np.zeros((SIDE,) * 3, np.float32)
    box = [slice(4, 36)] * 3
    box[2 - axis] = slice(17, 17 + THIN)  # axis in (x, y, z); the array is (z, y, x)
    data[tuple(box)] = 1.0
    return data


def lit_area(image, pixel):
    """World area of the image's lit pixels: above a tenth of its largest X-ray value."""
    return np.count_nonzero(image > 0.1 * image.max()) * pixel ** 2


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_a_slab_opens_showing_its_face(tmp_path, capsys, axis):
    """``clwave render`` with no view given opens a slab thin along x, y or z looking down that axis: the lit area of
    its X-ray picture is at least 90 % of its face's area seen at the view's tilt (cos of the angle between the view
    and the thin axis; the face 32 x 32 voxels), where the old opening (azimuth 30, elevation 20) showed the z and y
    slabs' edges (under 3/4 of that lit area)."""
    np.save(tmp_path / "slab.npy", slab(axis))
    code = main(["render", str(tmp_path / "slab.npy"), "--size", "48", "--raw", str(tmp_path / "r.npy"),
                 "-o", str(tmp_path / "r.png"), "--stats", str(tmp_path / "r.json")])
    assert code == 0, capsys.readouterr().err
    meta = json.loads((tmp_path / "r.json").read_text())
    camera = meta["camera"]
    assert (camera["azimuth"], camera["elevation"]) == SLAB_VIEWS[axis]
    n = view_frame(*SLAB_VIEWS[axis])[0]
    face = 32.0 * 32.0 * abs(n[axis])  # the face's projected area, world units (spacing 1)
    image = np.load(tmp_path / "r.npy")[..., 0]
    assert lit_area(image, meta["pixel"]) >= 0.9 * face
    if axis:  # the old opening, for the same model and framing: the slab's edge, a smaller lit area
        wv = clwave.WaveletVolume.from_volume(clwave.Volume(slab(axis))).threshold(keep=0.05)
        old = clwave.splat(wv, clwave.Camera(*OPENING, size=48))
        assert lit_area(old.image[..., 0], old.meta["pixel"]) < 0.75 * lit_area(image, meta["pixel"])


def test_a_cube_and_a_noisy_slab_open_as_before_and_as_a_slab():
    """A cube keeps the usual opening; a noisy slab whose box is a cube (the noise fills it) opens on its face."""
    cube = np.zeros((SIDE,) * 3, np.float32)
    cube[8:32, 8:32, 8:32] = 1.0
    assert opening_view(clwave.WaveletVolume.from_volume(clwave.Volume(cube))) == dict(azimuth=OPENING[0],
                                                                                       elevation=OPENING[1])
    noisy = slab(2) + np.random.default_rng(1).normal(0, 0.05, (SIDE,) * 3).astype(np.float32)
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(noisy), wavelet="linear", levels=2)
    assert opening_view(wv) == dict(azimuth=SLAB_VIEWS[2][0], elevation=SLAB_VIEWS[2][1])


def noisy_ball(n=64, radius=6, sigma=0.03, seed=29):
    """A ball of 1 of ``radius`` voxels off the centre of an ``n``^3 box of Gaussian noise; the ball's world centre."""
    z, y, x = np.mgrid[:n, :n, :n]
    centre = np.array([0.6, 0.4, 0.5]) * n  # voxel (x, y, z)
    data = np.random.default_rng(seed).normal(0, sigma, (n,) * 3).astype(np.float32)
    data += ((x - centre[0]) ** 2 + (y - centre[1]) ** 2 + (z - centre[2]) ** 2 < radius ** 2).astype(np.float32)
    return data, centre - (n - 1) / 2.0


def content_voxels(data, n=64):
    """World (x, y, z) centres of the voxels of the objects (of 1) in ``data`` (noise of deviation 0.03): above 0.5."""
    return np.argwhere(data > 0.5)[:, ::-1] - (n - 1) / 2.0


MODELS = [("linear", dict(noise=3)), ("haar", dict(keep=0.05)), ("cubic", dict(keep=1)), ("cubic", dict(keep=0.05))]


@pytest.mark.parametrize("wavelet, rule", MODELS)
def test_a_small_object_in_a_noisy_box_fills_the_frame(wavelet, rule):
    """Every voxel of a noisy box is non-zero, so the content box is the whole box (the ball of 12 voxels across a
    64^3 box: 11 % of the default frame's width); the frame holds the content above the noise instead: every voxel of
    the ball inside the framed box (so ``fit="box"`` crops none of it), and the ball at least 45 % of the frame's width
    (58 % where the box is the ball's: the frame holds the box's sphere)."""
    data, centre = noisy_ball()
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), wavelet=wavelet)
    wv.measure_noise()
    model = wv.threshold(**rule)
    whole = clwave.Camera(size=32).view(clwave.Volume(data))
    view = clwave.Camera(size=32).view(model)
    width = view.pixel * 32
    assert 12.0 / (whole.pixel * 32) < 0.12
    assert 12.0 / width >= 0.45
    lo, hi = framed_box(model)
    voxels = content_voxels(data)
    assert len(voxels) > 500 and ((voxels >= lo) & (voxels <= hi)).all()  # the ball, 4/3 pi 6^3 = 905 voxels


@pytest.mark.parametrize("wavelet, rule", MODELS)
def test_two_objects_apart_in_a_noisy_box_are_both_framed(wavelet, rule):
    """Two balls of radius 5 at opposite corners of a 64^3 box of noise: every voxel of both inside the framed box,
    which is within 4 voxels (two cells of level 1) of their voxels' box on every side."""
    z, y, x = np.mgrid[:64, :64, :64]
    data = np.random.default_rng(7).normal(0, 0.03, (64,) * 3).astype(np.float32)
    for cx, cy, cz in ((16, 18, 20), (46, 44, 40)):
        data += ((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2 < 25).astype(np.float32)
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), wavelet=wavelet)
    wv.measure_noise()
    lo, hi = framed_box(wv.threshold(**rule))
    voxels = content_voxels(data)
    assert ((voxels >= lo) & (voxels <= hi)).all()
    assert (lo >= voxels.min(axis=0) - 4).all() and (hi <= voxels.max(axis=0) + 4).all()


def test_the_turntable_frames_a_noisy_objects_content(tmp_path, capsys):
    """``clwave render --turntable`` of the noisy ball (linear, --noise 3): each view's lit pixels (above a tenth of
    its largest value) span at least 40 % of the image's width, where its content box framed 11 %."""
    data, _ = noisy_ball()
    np.save(tmp_path / "ball.npy", data)
    code = main(["render", str(tmp_path / "ball.npy"), "--wavelet", "linear", "--noise", "3", "--size", "32",
                 "--turntable", "3", "-o", str(tmp_path / "t.gif"), "--raw", str(tmp_path / "t.npy")])
    assert code == 0, capsys.readouterr().err
    for view in np.load(tmp_path / "t.npy")[..., 0]:
        columns = np.flatnonzero((view > 0.1 * view.max()).any(axis=0))
        assert (columns[-1] - columns[0] + 1) / 32 >= 0.4


def test_a_clean_model_frames_its_content_box():
    """A clean volume (no noise measured) is framed by its non-zero voxels, as before."""
    cube = np.zeros((SIDE,) * 3, np.float32)
    cube[8:20, 8:32, 8:32] = 1.0
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(cube))
    wv.measure_noise()
    lo, hi = framed_box(wv.threshold(keep=0.05))
    assert np.allclose(lo, wv.content_box()[0]) and np.allclose(hi, wv.content_box()[1])


def test_a_photo_stack_opens_with_its_top_row_at_the_top_and_its_left_column_at_the_left(tmp_path, capsys):
    """A folder of 4 RGB photos, a slab thin along z, opens from -z with y down (camera.PHOTO_SLAB_VIEW) as image
    viewers show a photo: the red band of each photo's first rows lies in the image's upper half and the green band of
    its first columns in the left half (from +z, as a grey tomogram opens, it read upside down)."""
    from PIL import Image

    from clwave.model.camera import PHOTO_SLAB_VIEW

    (tmp_path / "s").mkdir()
    for k in range(4):
        photo = np.full((24, 32, 3), 60, np.uint8)
        photo[:6], photo[:, :5] = (255, 0, 0), (0, 255, 0)  # the top rows red, the left columns green
        Image.fromarray(photo).save(tmp_path / "s" / f"s{k}.png")
    assert main(["render", str(tmp_path / "s"), "--size", "48", "--raw", str(tmp_path / "r.npy"), "-o",
                 str(tmp_path / "r.png"), "--stats", str(tmp_path / "r.json")]) == 0, capsys.readouterr().err
    camera = json.loads((tmp_path / "r.json").read_text())["camera"]
    assert (camera["azimuth"], camera["elevation"]) == PHOTO_SLAB_VIEW
    image = np.load(tmp_path / "r.npy")
    rows, columns = np.mgrid[:48, :48]
    red, green = (np.clip(image[..., c] - image[..., 2], 0, None) for c in (0, 1))  # beyond the grey
    assert np.average(rows, weights=red) < 20 and np.average(columns, weights=green) < 20


def test_a_noisy_volume_of_both_signs_frames_its_box():
    """A crop of a CT in Hounsfield units (tissue at 40 across its border, a lung at -1000 and a bone at 700 inside,
    noise 15): its tissue is content, not background, so it frames its whole box; cut to the lung and the bone (the
    values above the noise about 0) it cropped the tissue (test_subtract's CT framed two ways)."""
    data = np.full((24, 24, 24), 40.0, np.float32)
    data[6:10, 6:10, 6:10], data[13:17, 13:17, 13:17] = -1000.0, 700.0
    data += np.random.default_rng(30).normal(0, 15, data.shape).astype(np.float32)
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), wavelet="linear", levels=2)
    assert wv.measure_noise()[0] == pytest.approx(15, rel=0.2)
    lo, hi = framed_box(wv)
    np.testing.assert_array_equal(lo, [-12.0] * 3)
    np.testing.assert_array_equal(hi, [12.0] * 3)
