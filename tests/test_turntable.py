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
