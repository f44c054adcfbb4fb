"""Clipping by voxel ranges (annot30, trial30's finding 12): ``Clip.of_voxels`` (``--clip-voxels Z0:Z1,Y0:Y1,X0:X1``)
gives the clip box in indices of the input array, in its axis order, turned into world coordinates in the model's own
geometry (spacing, origin, and the orientation the input was turned by).  Checked against world numbers worked out by
hand, and end to end against an independent answer: a marker slab at known indices clipped away renders as the data
with the marker removed, under RAI (time down: the array's axis 0 flipped) and anisotropic spacing."""

from types import SimpleNamespace

import numpy as np
import pytest

from clwave.cli import main
from clwave.errors import InputError
from clwave.model.clip import Clip
from test_outputs_formats import decode_png


def test_a_voxel_box_is_its_voxels_outer_faces_in_world_coordinates():
    """trial30's cube: (TWT 256, crossline 150, inline 200) at 12, 12.5, 25, time down (RAI), centred on (10, 20, 30).
    Samples 100:200 flipped count from z's top: model voxels 56:156 of 256, z from (56 - 128) 12 to (156 - 128) 12;
    crosslines 50:100, y from (50 - 75) 12.5 to (100 - 75) 12.5; every inline, x from -100 25 to 100 25."""
    cube = SimpleNamespace(shape=(256, 150, 200), spacing=(12.0, 12.5, 25.0), origin=(10.0, 20.0, 30.0))
    clip = Clip.of_voxels(cube, "100:200,50:100,:", orientation="RAI")
    assert clip.lo == (10 - 2500.0, 20 - 312.5, 30 - 864.0) and clip.hi == (10 + 2500.0, 20 + 312.5, 30 + 336.0)
    same = Clip.of_voxels(cube, [(100, 200), slice(50, 100), None], orientation="RAI")
    assert (same.lo, same.hi) == (clip.lo, clip.hi)
    unturned = Clip.of_voxels(cube, "100:200,50:100,:")  # no orientation: the array's axes are the model's
    assert unturned.lo[2] == 30 + (100 - 128) * 12.0 and unturned.hi[2] == 30 + (200 - 128) * 12.0
    lps = Clip.of_voxels(cube, ":,:10,190:", orientation="LPS")  # x and y flipped, z not
    assert lps.lo[:2] == (10 - 2500.0, 20 + (140 - 75) * 12.5) and lps.hi[:2] == (10 - 2250.0, 20 + 937.5)
    planed = Clip.of_voxels(cube, ":,:,:", planes=[((0, 0, 0), (1, 0, 0))])
    assert planed.planes == (((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)),)


@pytest.mark.parametrize("voxels, words", [
    ("100:300,:,:", "voxels 100:300 along the array's axis 0 (z) must lie in 0:256, the start below the stop"),
    (":,80:80,:", "voxels 80:80 along the array's axis 1 (y) must lie in 0:150"),
    (":,:,-5:", "voxels -5:200 along the array's axis 2 (x) must lie in 0:200"),
    ("1:2,3:4", "must be three ranges of whole voxel indices START:STOP"),
    ("1.5:2,:,:", "must be three ranges of whole voxel indices START:STOP"),
    ([(0, 1), (0, 1), (0, True)], "must be three ranges of whole voxel indices START:STOP"),
])
def test_a_range_out_of_the_array_or_empty_is_refused_in_one_line(voxels, words):
    cube = SimpleNamespace(shape=(256, 150, 200), spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0))
    with pytest.raises(InputError, match=words.replace("(", r"\(").replace(")", r"\)")):
        Clip.of_voxels(cube, voxels)


def test_a_model_of_a_file_turned_by_its_header_is_refused(tmp_path):
    nib = pytest.importorskip("nibabel")
    path = tmp_path / "a.nii.gz"
    nib.save(nib.Nifti1Image(np.zeros((4, 5, 6), np.float32), np.eye(4)), path)
    model = SimpleNamespace(shape=(6, 5, 4), spacing=(1.0,) * 3, origin=(0.0,) * 3, provenance=dict(file=str(path)))
    with pytest.raises(InputError, match="was turned into RAS\\+ by its header, so its array's axes are not the "
                                         "model's: give a box in world coordinates"):
        Clip.of_voxels(model, ":,:,:")


SHAPE, SPACING = (24, 16, 20), "2,1,1.5"  # (z, y, x): anisotropic


def cube(tmp_path, marker: bool):
    """A smooth cube of (z, y, x) values 1 .. 2 (a ramp along z), with a bright slab at array rows z 3:6 (10 more)."""
    z = np.linspace(1.0, 2.0, SHAPE[0], dtype=np.float32)[:, None, None]
    data = np.broadcast_to(z, SHAPE).copy()
    if marker:
        data[3:6] += 10.0
    path = tmp_path / ("marked.npy" if marker else "plain.npy")
    np.save(path, data)
    return path


def render(tmp_path, source, voxels, name):
    out = tmp_path / f"{name}.png"
    assert main(["render", str(source), "--spacing", SPACING, "--orientation", "RAI", "--wavelet", "linear",
                 "--levels", "1", "--keep", "1", "--method", "raytrace", "--xray", "--tolerance", "1e-4", "--size",
                 "40", "--azimuth", "0", "--elevation", "0", "--window", "0,120", "--bit-depth", "16",
                 "--clip-voxels", voxels, "-o", str(out), "--force"]) == 0
    return decode_png(out)[1].astype(np.int64)


def test_a_marker_slab_clipped_away_renders_as_the_data_without_it(tmp_path, capsys):
    """Under RAI the array's rows z 3:6 are at the model's top (rows 18:21 of 24): clipped to rows 9: of the array
    (their rows 0:15), 3 voxels clear of the marker (the linear model's reach is 1), the marked cube's X-ray equals
    the plain cube's, pixel for pixel at 16 bits within the tolerance's few levels; clipped to rows 0:9, which hold
    it, it is brighter by the marker's integral.  An unturned reading of the indices (rows 9: of the model) would
    keep the marker, and differ."""
    marked, plain = cube(tmp_path, True), cube(tmp_path, False)
    away = render(tmp_path, marked, "9:,:,:", "away")
    np.testing.assert_allclose(away, render(tmp_path, plain, "9:,:,:", "plain_away"), atol=3)
    assert away.max() > 1000  # not a blank image: the cube's rows 9: are there
    kept, plain_kept = render(tmp_path, marked, "0:9,:,:", "kept"), render(tmp_path, plain, "0:9,:,:", "plain_kept")
    # the marker's integral along x across the slab: 10 over 20 voxels of 1.5, 300 of 120 (the window's top): white
    assert (kept - plain_kept).max() > 30000
    capsys.readouterr()
    for extra, words in [(["--clip-voxels", "0:30,:,:"], "--clip-voxels 0:30,:,:: voxels 0:30 along the array's axis "
                                                         "0 (z) must lie in 0:24"),
                         (["--clip-voxels", "0:9,:,:", "--clip-box", "0,0,0,1,1,1"], "--clip-box 0,0,0,1,1,1 and "
                                                                                    "--clip-voxels 0:9,:,: each give "
                                                                                    "the box: give one of them"),
                         (["--clip-voxels", "0:9"], "--clip-voxels 0:9: voxels '0:9' must be three ranges")]:
        argv = ["render", str(marked), "--method", "raytrace", "--xray", "--size", "8", "-o", str(tmp_path / "x.png")]
        assert main(argv + extra) == 2
        err = capsys.readouterr().err
        assert words in err and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "x.png").exists()
