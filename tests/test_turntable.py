"""clwave.turntable: the API's turntable is the command line's, frame for frame; its window, stack and refusals."""

import json

import imageio.v3 as iio
import numpy as np
import pytest

import clwave
from clwave.cli import main
from clwave.model.wavelet import WaveletVolume


def cli(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def hydrogen():
    """The command line's model of ``phantom:hydrogen:16 --levels 1`` (its default --keep 0.05)."""
    return WaveletVolume.from_volume(clwave.phantom("hydrogen", 16), levels=1).threshold(keep=0.05)


def test_the_apis_splatted_gif_is_the_command_lines(tmp_path, capsys, hydrogen):
    """An X-ray turntable saved by the API holds the CLI's frames bit for bit (the CLI splats an 8-bit GIF through
    the automatic window with coarse=1e-3, docs/splatting.md §4), and its stack the CLI's --raw."""
    code, _, err = cli(capsys, "render", "phantom:hydrogen:16", "--levels", "1", "--size", "12x16", "--azimuth", "10",
                       "--turntable", "5", "-o", str(tmp_path / "cli.gif"), "--raw", str(tmp_path / "cli.npy"))
    assert code == 0, err
    turn = clwave.turntable(hydrogen, 5, clwave.Camera(10, 20, size=(12, 16)), coarse=1e-3)
    turn.save(tmp_path / "api.gif")
    turn.save(tmp_path / "api.npy")
    frames = iio.imread(tmp_path / "api.gif", index=None)
    assert frames.shape == (5, 12, 16, 3)
    assert np.array_equal(frames, iio.imread(tmp_path / "cli.gif", index=None))
    assert np.array_equal(np.load(tmp_path / "api.npy"), np.load(tmp_path / "cli.npy"))


def test_the_apis_ray_traced_gif_is_the_command_lines(tmp_path, capsys):
    """A shaded turntable of a classified .clw, perspective, over white: the CLI's frames bit for bit."""
    model = tmp_path / "h.clw"
    code, _, err = cli(capsys, "compress", "phantom:hydrogen:16", "--tf", "hydrogen", "--levels", "1", "-o", str(model))
    assert code == 0, err
    code, _, err = cli(capsys, "render", str(model), "--method", "raytrace", "--tolerance", "1e-2", "--perspective",
                       "--fov", "40", "--size", "10", "--turntable", "3", "--background", "1,1,1",
                       "-o", str(tmp_path / "cli.gif"))
    assert code == 0, err
    camera = clwave.Camera(30, 20, size=10, perspective=True, fov=40)
    turn = clwave.turntable(WaveletVolume.open(model), 3, camera, method="raytrace", tolerance=1e-2)
    assert turn.window() is None and turn.images.shape == (3, 10, 10, 4)
    turn.save(tmp_path / "api.gif", background=(1, 1, 1))
    assert np.array_equal(iio.imread(tmp_path / "api.gif", index=None), iio.imread(tmp_path / "cli.gif", index=None))


def test_views_cameras_window_and_figures(tmp_path, hydrogen):
    """View i is the camera turned by 360 i / n degrees (each the API's own splat); one window, the 0.5 and 99.5
    percentiles of every view's values together; the .json holds each view's time and camera."""
    turn = clwave.turntable(hydrogen, 4, clwave.Camera(-20, 35, size=8))
    assert len(turn) == 4
    for i, res in enumerate(turn.results):
        assert np.array_equal(res.image, clwave.splat(hydrogen, clwave.Camera(-20 + 90 * i, 35, size=8)).image)
    lo, hi = np.percentile(turn.images, (0.5, 99.5))
    assert np.allclose(turn.window(), (lo, hi), rtol=1e-6)
    grey = np.round(255 * np.clip((turn.images[..., 0] - lo) / (hi - lo), 0, 1))
    assert np.abs(np.stack(turn.pictures()).astype(float) - grey).max() <= 1
    turn.save(tmp_path / "t.json")
    meta = json.loads((tmp_path / "t.json").read_text())
    assert [v["camera"]["azimuth"] for v in meta["turntable_views"]] == [-20, 70, 160, 250]
    assert len(meta["turntable_seconds"]) == 4 and all(s > 0 for s in meta["turntable_seconds"])


@pytest.mark.parametrize("call, message", [
    (dict(n=0), "n=0 must be the number of views, a whole number >= 1 (e.g. 24)"),
    (dict(n=2.5), "n=2.5 must be the number of views"),
    (dict(n=True), "n=True must be the number of views"),
    (dict(n="3"), "n='3' must be the number of views"),
    (dict(n=2, method="mip"), "method='mip' must be one of 'splat', 'raytrace'"),
    (dict(n=2, tolerance=1e-2), "splat takes no such option (got an unexpected keyword argument 'tolerance'): "
                                "see help(clwave.splat)"),
    (dict(n=2, method="raytrace", coarse=1e-3), "raytrace takes no such option"),
    (dict(n=2, camera=clwave.ConeBeam(40, 80, 8)), "camera=ConeBeam must be a clwave.Camera"),
])
def test_bad_turntables_are_refused_in_one_line_before_any_view(hydrogen, call, message):
    with pytest.raises(clwave.InputError) as e:
        clwave.turntable(hydrogen, **call)
    assert message in str(e.value) and "\n" not in str(e.value)


def test_a_turntable_beyond_the_host_memory_is_refused_before_any_view(tmp_path, capsys, hydrogen, monkeypatch):
    """100 views of 8 x 8 hold 100 x 64 x 32 bytes (images, their stack, pictures): refused where 1 byte less is
    available, before a view is made (--turntable 100000000 ran for minutes towards an exhausted memory)."""
    from clwave.device import memory
    from clwave.turntable import VIEW_PIXEL_BYTES, turntable_cameras

    assert VIEW_PIXEL_BYTES == 4 * 4 + 4 * 3 + 4  # float32 RGBA, their colour channels stacked, an 8-bit picture
    camera = clwave.Camera(size=8)
    monkeypatch.setattr(memory, "available_bytes", lambda: 100 * 64 * 32)
    assert len(turntable_cameras(camera, 100)) == 100  # just fits
    monkeypatch.setattr(memory, "available_bytes", lambda: 100 * 64 * 32 - 1)
    monkeypatch.setattr(clwave.Camera, "rotated", lambda *a: pytest.fail("a view was made"))
    with pytest.raises(memory.HostMemoryError, match=r"^a turntable of 100 8x8 views needs about 200 KiB, .*; give "
                                                     r"fewer views"):
        clwave.turntable(hydrogen, 100, camera)
    code, _, err = cli(capsys, "render", "phantom:hydrogen:16", "--size", "8", "--turntable", "100", "-o",
                       str(tmp_path / "t.gif"))
    assert code == 2 and err.count("\n") == 1 and "a turntable of 100 8x8 views needs about 200 KiB" in err, err
    assert list(tmp_path.iterdir()) == []


def test_bad_saves_are_refused_and_write_nothing(tmp_path, capsys, hydrogen):
    turn = clwave.turntable(hydrogen, 2, clwave.Camera(size=8))
    for path, options, message in [
        ("t.gif", dict(frame_time=0), "frame_time=0 must be the seconds each frame is shown, from 0.02"),
        ("t.gif", dict(frame_time=float("nan")), "frame_time=nan must be the seconds each frame is shown"),
        ("t.gif", dict(frame_time="0.1"), "frame_time='0.1' must be the seconds each frame is shown"),
        ("t.gif", dict(frame_time=700), "to 655.35 (a GIF's longest)"),
        ("t.png", {}, "t.png: use .gif, .npy or .json"),
        ("t.npy", dict(window=(0, 1)), "window= set a .gif's pictures; "),
    ]:
        with pytest.raises(clwave.InputError) as e:
            turn.save(tmp_path / path, **options)
        assert message in str(e.value)
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(clwave.InputError, match="a Turntable needs at least one view"):
        clwave.Turntable([])
    code, _, err = cli(capsys, "render", "phantom:hydrogen:16", "--turntable", "0", "-o", str(tmp_path / "z.gif"))
    assert code == 2 and err.count("\n") == 1 and "--turntable 0 needs N >= 1" in err


def _frame(camera):
    """A camera's (n, u, v) as the rows of a matrix."""
    return np.array(camera.basis())


@pytest.mark.parametrize("axis", ["x", "y", (1.0, -2.0, 2.0)])
def test_a_turntable_about_any_axis_turns_the_camera_by_a_rotation_matrix(axis):
    """trial26 finding 7: a turntable turned about world z only (a FITS cube's spectral axis).  View i of a turntable
    about ``axis`` is the first camera's frame (n, u, v) turned by 360 i / n degrees about it, right-handed: SciPy's
    rotation matrix of that angle about the axis, an independent answer; and a camera made directly with the
    azimuth, elevation and roll the turn gives resolves to the same frame."""
    from scipy.spatial.transform import Rotation

    from clwave.turntable import turntable_cameras

    unit = {"x": (1, 0, 0), "y": (0, 1, 0)}.get(axis, axis)
    unit = np.asarray(unit, float) / np.linalg.norm(unit)
    first = clwave.Camera(-20, 35, size=8)
    cameras = turntable_cameras(first, 5, axis=axis)
    for i, cam in enumerate(cameras):
        turn = Rotation.from_rotvec(np.radians(72.0 * i) * unit).as_matrix()
        assert np.allclose(_frame(cam), _frame(first) @ turn.T, atol=1e-12), i
        again = clwave.Camera.from_dict(json.loads(json.dumps(cam.to_dict())))
        assert np.allclose(_frame(again), _frame(cam), atol=1e-12)
        assert np.allclose(_frame(eval(repr(cam), {"Camera": clwave.Camera})), _frame(cam), atol=1e-12)
    z = turntable_cameras(first, 5, axis="z")
    assert [c.to_dict() for c in z] == [c.to_dict() for c in turntable_cameras(first, 5)]
    assert [c.azimuth for c in z] == [-20, 52, 124, 196, 268] and all(c.roll == 0 for c in z)


@pytest.mark.parametrize("axis, unit", [((1e308, 1e308, 0), (0.5 ** 0.5, 0.5 ** 0.5, 0)), ((0, -1e-200, 0), (0, -1, 0)),
                                        ((3, 0, 4), (0.6, 0, 0.8))])
def test_a_direction_of_any_finite_length_is_its_unit_vector(axis, unit):
    """A finite direction whose squares overflow or underflow float64 is a direction still (no overflow warning,
    filterwarnings=error), not refused as all zero or infinite."""
    from clwave.turntable import turntable_axis

    assert np.allclose(turntable_axis(axis), unit, rtol=0, atol=1e-15)


def test_a_turntable_about_the_view_axis_turns_the_image(tmp_path, capsys):
    """Seen along x (azimuth 0, elevation 0), a turn of 90 degrees about x turns the image a quarter clockwise
    (u = y to z, v = z to -y): each ray-traced X-ray view is the first one turned by numpy.rot90, for a volume
    with no symmetry, and each splatted one too (the splats' footprints in a rolled frame); the command line's
    --turntable-axis 1,0,0 gives the API's views."""
    data = np.zeros((12, 12, 12), np.float32)
    data[2:9, 3:6, 4:10] = 1.0
    data[6:8, 6:10, 5:7] = 2.0
    wv = WaveletVolume.from_volume(clwave.Volume(data), levels=1)
    turn = clwave.turntable(wv, 4, clwave.Camera(0, 0, size=16), method="raytrace", axis="x", absorption=False,
                            tolerance=1e-4)
    first = turn.images[0, ..., 0]
    peak = first.max()
    splats = clwave.turntable(wv, 4, clwave.Camera(0, 0, size=16), axis="x").images[..., 0]
    for i in range(1, 4):
        assert np.abs(turn.images[i, ..., 0] - np.rot90(first, -i)).max() < 1e-3 * peak, i
        assert np.abs(splats[i] - np.rot90(splats[0], -i)).max() < 1e-5 * peak, i
    np.save(tmp_path / "v.npy", data)
    code, _, err = cli(capsys, "render", str(tmp_path / "v.npy"), "--levels", "1", "--keep", "1", "--method",
                       "raytrace", "--xray", "--azimuth", "0", "--elevation", "0", "--size", "16", "--turntable", "4",
                       "--turntable-axis", "1,0,0", "--tolerance", "1e-4", "-o", str(tmp_path / "t.gif"), "--raw",
                       str(tmp_path / "t.npy"))
    assert code == 0, err
    assert np.abs(np.load(tmp_path / "t.npy") - turn.images).max() < 1e-3 * peak


@pytest.mark.parametrize("argv, message", [
    (["--turntable", "3", "--turntable-axis", "w"], "--turntable-axis w must be x, y, z or three numbers AX,AY,AZ"),
    (["--turntable", "3", "--turntable-axis", "0,0,0"], "--turntable-axis 0,0,0 must be a direction"),
    (["--turntable-axis", "x"], "--turntable-axis is for a --turntable"),
])
def test_bad_turntable_axes_are_one_line(tmp_path, capsys, argv, message):
    code, out, err = cli(capsys, "render", "phantom:hydrogen:16", "-o", str(tmp_path / "t.gif"), *argv)
    assert code == 2 and out == "" and err.count("\n") == 1 and message in err, err
    with pytest.raises(clwave.InputError, match="axis=.* must be"):
        clwave.turntable(None, 3, axis=(0, 0, 0))
