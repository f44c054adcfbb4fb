"""What a render records of its view (docs/coordinates.md §4): the camera as given, the pixel's world width, the
display window; enough to make the same picture again. And cameras' repr and to_dict/from_dict."""

import json

import numpy as np
import pytest

import clwave
from clwave import Camera, ConeBeam
from clwave.cli import main
from clwave.errors import InputError
from clwave.io.result import RenderResult, resolve_window
from clwave.model.wavelet import WaveletVolume


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    assert code == 0, err


def test_a_picture_is_made_again_from_its_stats(tmp_path, capsys):
    """render --stats; Camera.from_dict(stats["camera"]) and the window recorded make the same PNG, byte for byte."""
    png, raw, stats = tmp_path / "a.png", tmp_path / "a.npy", tmp_path / "a.json"
    run(capsys, "render", "phantom:hydrogen:16", "--levels", "2", "--keep", "0.2", "--azimuth", "37.5",
        "--elevation", "12", "--size", "24x32", "-o", str(png), "--raw", str(raw), "--stats", str(stats))
    meta = json.loads(stats.read_text())
    camera = Camera.from_dict(meta["camera"])
    assert (camera.azimuth, camera.elevation, camera.size, camera.extent) == (37.5, 12.0, (24, 32), None)
    assert meta["window"] == list(resolve_window(np.load(raw)[..., 0], "auto"))
    wv = WaveletVolume.from_volume(clwave.phantom("hydrogen", 16), levels=2).threshold(keep=0.2)
    assert meta["pixel"] == camera.view(wv).pixel
    again = tmp_path / "b.png"
    clwave.splat(wv, camera).save(again, window=tuple(meta["window"]))
    assert again.read_bytes() == png.read_bytes()


def test_a_turntable_records_each_view_and_its_one_window(tmp_path, capsys):
    raw, stats = tmp_path / "t.npy", tmp_path / "t.json"
    run(capsys, "render", "phantom:shepp-logan:16", "--levels", "1", "--size", "8x10", "--extent", "2.5",
        "--azimuth", "10", "--turntable", "4", "-o", str(tmp_path / "t.gif"), "--raw", str(raw), "--stats", str(stats))
    meta = json.loads(stats.read_text())
    views = meta["turntable_views"]
    assert [Camera.from_dict(v["camera"]).azimuth for v in views] == [10.0, 100.0, 190.0, 280.0]
    assert [v["pixel"] for v in views] == [2.5 / 10] * 4  # extent / W (docs/coordinates.md §2)
    assert meta["window"] == list(resolve_window(np.load(raw), "auto"))  # one window for the whole turn


def test_progressive_stats_record_the_final_images_window(tmp_path, capsys):
    stats = tmp_path / "p.json"
    run(capsys, "progressive", "phantom:shepp-logan:16", "--levels", "1", "--keep", "0.2", "--size", "12",
        "--steps", "2", "-o", str(tmp_path / "p.gif"), "--stats", str(stats))
    meta = json.loads(stats.read_text())["meta"]
    wv = WaveletVolume.from_volume(clwave.phantom("shepp-logan", 16), levels=1).threshold(keep=0.2)
    # every frame's window is the final image's: the last frame's (the sum in its order, not a fresh render's)
    final = list(clwave.progressive(wv, Camera.from_dict(meta["camera"]), steps=2))[-1].image
    assert meta["window"] == list(resolve_window(final, "auto"))


def test_shaded_stats_record_a_perspective_camera_and_no_window(tmp_path, capsys):
    stats = tmp_path / "r.json"
    run(capsys, "render", "phantom:hydrogen:16", "--tf", "hydrogen", "--levels", "1", "--method", "raytrace",
        "--size", "12x16", "--tolerance", "1e-2", "--perspective", "--fov", "40", "--distance", "5",
        "-o", str(tmp_path / "r.png"), "--stats", str(stats))
    meta = json.loads(stats.read_text())
    assert meta["window"] is None
    camera = Camera.from_dict(meta["camera"])
    assert (camera.perspective, camera.fov, camera.distance) == (True, 40.0, 5.0)
    # at the target, distance 5 from the eye: the image's height is 2 * 5 * tan(20 deg), over 12 rows
    assert meta["pixel"] == pytest.approx(2 * 5 * np.tan(np.radians(20)) / 12, rel=1e-12)


def test_a_cone_beams_meta_makes_it_again():
    """splat and ray tracing record a ConeBeam as its to_dict; the pixel is the detector's at the isocentre."""
    wv = WaveletVolume.from_volume(clwave.phantom("hydrogen", 16), levels=1)
    cb = ConeBeam(40.0, 60.0, (6, 8), pixel=0.3, azimuth=20.0, roll=10.0)
    for result in (clwave.splat(wv, cb), clwave.raytrace(wv, cb, absorption=False, tolerance=1e-2)):
        again = ConeBeam.from_dict(json.loads(json.dumps(result.meta["camera"])))
        assert np.array_equal(again.matrix(), cb.matrix())
        assert result.meta["pixel"] == pytest.approx(0.3 * 40.0 / 60.0, rel=1e-12)  # magnified by dsd / dso
    meta = clwave.SplatRenderer(wv).render(cb.view(wv)).meta  # a view resolved already (clwave drr's): no camera
    assert "camera" not in meta and meta["pixel"] == pytest.approx(0.2, rel=1e-12)
    frames = list(clwave.progressive(wv, Camera(0, 0, 8), steps=2))
    assert all(Camera.from_dict(f.meta["camera"]).size == (8, 8) for f in frames)
    # a frame traced on a reduced image records the camera given, whose (upsampled) image it is
    frames = list(clwave.progressive(wv, Camera(0, 0, 64), method="raytrace", absorption=False, tolerance=1e-2))
    assert [f.reduction for f in frames] == [2, 1]
    assert all(f.meta["camera"] == Camera(0, 0, 64).to_dict() and f.meta["pixel"] == frames[-1].meta["pixel"]
               for f in frames)


CAMERAS = [Camera(37.5, 12, size=(900, 1600), extent=300.0), Camera(perspective=True, fov=20),
           Camera(1, 2, 8, target=(1, 2.5, 3), fit="box"), Camera(0.1, -0.2, (3, 5), perspective=True, distance=7.25),
           Camera(45, 30, 16).rotated(12.5), Camera(0, 0, 7, extent=3.0).reduced(2, Camera(0, 0, 7).view(
               clwave.phantom("shepp-logan", 8)))]
CONES = [ConeBeam(1000, 1500, (4, 6), pixel=(2.0, 1.5), offset=(3, -4), azimuth=30, elevation=5, roll=5,
                  isocentre=(1, 2, 3)), ConeBeam(100, 150, 8)]
CONES += [CONES[0].reduced(2).reduced(3), ConeBeam.from_matrix(CONES[0].matrix(), (4, 6)),
          ConeBeam.from_matrix(CONES[0].matrix(), (4, 6), isocentre=(1, 2, 3)).reduced(2)]


@pytest.mark.parametrize("camera", CAMERAS + CONES, ids=repr)
def test_repr_and_to_dict_make_the_camera_again(camera):
    state = ("n", "u", "v", "source", "size", "slope", "principal", "isocentre", "dso", "dsd", "pixel", "offset") \
        if isinstance(camera, ConeBeam) else ("azimuth", "elevation", "size", "target", "extent", "perspective",
                                              "distance", "fov", "fit")
    d = camera.to_dict()
    for again in (eval(repr(camera)), type(camera).from_dict(json.loads(json.dumps(d)))):
        assert type(again) is type(camera) and again.to_dict() == d and repr(again) == repr(camera)
        for name in state:
            assert np.array_equal(getattr(again, name), getattr(camera, name), equal_nan=False), name


def test_the_repr_shows_what_is_not_default():
    assert repr(CAMERAS[0]) == "Camera(azimuth=37.5, elevation=12.0, size=(900, 1600), extent=300.0)"
    assert repr(CAMERAS[1]) == "Camera(azimuth=30.0, elevation=20.0, size=(512, 512), perspective=True, fov=20.0)"
    assert repr(CONES[1]) == "ConeBeam(dso=100.0, dsd=150.0, size=(8, 8))"


@pytest.mark.parametrize("make, d, words", [
    (Camera.from_dict, dict(kind="camera", zoom=2), "unknown field(s) zoom"),
    (Camera.from_dict, dict(kind="cone_beam", dso=1, dsd=2, size=4), "of kind 'camera'"),
    (Camera.from_dict, [30, 20], "not 'list'"),
    (Camera.from_dict, dict(size=[4, 4], fov=20), "perspective"),
    (ConeBeam.from_dict, dict(kind="cone_beam", dso=1, size=4), "needs dso, dsd, size"),
    (ConeBeam.from_dict, dict(matrix=np.eye(3, 4).tolist(), size=4, dso=3), "isocentre alone"),
    (ConeBeam.from_dict, dict(dso=1, dsd=2, size=4, reduced=[0]), "whole numbers >= 1"),
])
def test_a_bad_description_is_one_line(make, d, words):
    with pytest.raises(InputError, match=None) as info:
        make(d)
    assert words in str(info.value) and "\n" not in str(info.value)


def test_a_shaded_result_has_no_window():
    assert RenderResult(np.zeros((2, 2, 4), np.float32), dict(mode="emission-absorption")).display_window() is None
    assert RenderResult(np.zeros((2, 2, 1), np.float32)).display_window((0, 2)) == (0.0, 2.0)
