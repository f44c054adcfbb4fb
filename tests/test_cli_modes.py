"""Options of one mode given in another are refused, never ignored; what a command tells and exits with."""

import pytest

import clwave
from clwave.cli import main
from clwave.errors import InputError

RENDER = ["render", "phantom:hydrogen:16", "--levels", "1", "--size", "8"]


@pytest.mark.parametrize("extra, needle", [
    (["--fov", "60"], "--fov sets a perspective view: add --perspective, or leave it out"),
    (["--distance", "50"], "--distance sets a perspective view: add --perspective, or leave it out"),
    (["--fov", "60", "--distance", "50"], "--fov and --distance set a perspective view: add --perspective, or leave "
                                          "them out"),
])
@pytest.mark.parametrize("command", ["render", "progressive"])
def test_perspective_options_without_perspective_are_refused_before_any_work(tmp_path, capsys, monkeypatch, extra,
                                                                             needle, command):
    """They changed nothing (an orthographic image, as without them), as --frame-time without --turntable would."""
    from clwave.cli import progressive, render

    monkeypatch.setattr(render if command == "render" else progressive, "build_model",
                        lambda *a, **k: pytest.fail("work started"))
    out = tmp_path / ("x.png" if command == "render" else "x.gif")
    assert main([command, *RENDER[1:], "-o", str(out), *extra]) == 2
    assert capsys.readouterr().err == f"clwave: error: {needle}\n" and not out.exists()


@pytest.mark.parametrize("kwargs, needle", [
    (dict(fov=60), "fov= sets a perspective camera's view: give perspective=True too, or leave fov= out"),
    (dict(distance=5), "distance= sets a perspective camera's view: give perspective=True too, or leave distance= out"),
])
def test_a_camera_refuses_perspective_arguments_without_perspective(kwargs, needle):
    with pytest.raises(InputError) as err:
        clwave.Camera(**kwargs)
    assert str(err.value) == needle
    camera = clwave.Camera(perspective=True, **kwargs)  # with it, taken
    assert camera.fov == kwargs.get("fov", 30.0) and camera.distance == kwargs.get("distance")


def test_an_orthographic_cameras_reduced_view_stays_orthographic():
    """A progressive frame's reduced camera (Camera.reduced) gives no perspective arguments to an orthographic one."""
    volume = clwave.phantom("hydrogen", 8)
    camera = clwave.Camera(size=8)
    reduced = camera.reduced(2, camera.view(volume))
    assert not reduced.perspective and reduced.size == (4, 4) and reduced.view(volume).pixel == \
        pytest.approx(2 * camera.view(volume).pixel)


def test_a_2d_nifti_is_told_the_voxels_an_axis_clwave_needs(tmp_path, capsys):
    """A 64 x 64 slice: "at least 2 voxels an axis", what the transform needs (it said "one voxel")."""
    import nibabel
    import numpy as np

    path = tmp_path / "slice.nii.gz"
    nibabel.save(nibabel.Nifti1Image(np.ones((64, 64), np.float32), np.eye(4)), path)
    assert main(["compress", str(path), "-o", str(tmp_path / "x.clw")]) == 2
    err = capsys.readouterr().err
    assert "clwave reads 3-D volumes with at least 2 voxels an axis (stack 2-D slices into one first)" in err


def test_render_help_says_the_png_is_always_written(capsys):
    with pytest.raises(SystemExit):
        main(["render", "--help"])
    assert "always written (--raw adds the float32 values beside it)" in " ".join(capsys.readouterr().out.split())
