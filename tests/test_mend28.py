"""Defects left by the twenty-second session's fuzzing and review (mend28; docs/known-gaps.md §15): each pinned by a
test that failed before its fix."""

import warnings

import numpy as np
import pytest

import clwave
from clwave.errors import FileFormatError, InputError
from clwave.model.volume import ORIGIN_VOXELS
from test_cli import run
from test_hardening import crafted


def _blob(n=12):
    """A smooth (n, n, n) blob off the centre, non-zero in every channel's support (its own answer nowhere)."""
    z, y, x = np.mgrid[:n, :n, :n].astype(np.float32)
    return np.exp(-((x - 5) ** 2 + (y - 6) ** 2 / 2 + (z - 7) ** 2 / 3) / 8).astype(np.float32)


@pytest.mark.parametrize("spacing", [1.0, 0.3])
def test_a_volume_far_from_the_world_origin_ray_traces_as_at_it(spacing):
    """The ray tracer took world points in float32: a volume centred 1e9 voxels from 0 drew its rays 64 voxels apart
    (0.19 off at origin 1e9, 5e-3 at 1e6 with tolerance 1e-3). Its images, shaded, X-ray and clipped, are the ones
    at origin 0 (the kernel's world is about the volume's centre)."""
    tf = clwave.TransferFunction([(0.0, 1, 1, 1, 0.0), (1.0, 1, 0.5, 0.2, 2.0)])
    camera = clwave.Camera(30, 20, size=24)
    images = []
    for origin in [(0.0, 0.0, 0.0), (1e9 * spacing, -1e9 * spacing, 5e8 * spacing)]:
        volume = clwave.Volume(_blob(), spacing=spacing, origin=origin)
        model = clwave.WaveletVolume.from_volume(tf.classify(volume), levels=1)
        clip = clwave.Clip(planes=[(np.array(origin) + (spacing, 0, 0), (1, 0, 0))])
        images.append([clwave.raytrace(model, camera, tolerance=1e-3).image,
                       clwave.raytrace(model, camera, tolerance=1e-3, absorption=False).image,
                       clwave.raytrace(model, camera, tolerance=1e-3, clip=clip).image])
    for far, near in zip(images[1], images[0]):
        assert np.abs(near).max() > 0.1
        np.testing.assert_allclose(far, near, atol=1e-3)


def test_an_origin_past_the_voxels_float64_places_is_refused_naming_origin(tmp_path, capsys):
    """Origin 1e17 at spacing 1: a volume whose voxels float64 cannot place (the content box's corners one point)
    was saved as a .clw that could not be opened ("low below high"), and a splat of it divided by zero. Volume,
    every loader (NRRD, NIfTI) and a .clw header refuse it in one line naming the origin; ORIGIN_VOXELS itself is
    saved and opened."""
    with pytest.raises(InputError, match=r"origin .* lies more than 1e\+12 voxels from 0.*give origin= nearer"):
        clwave.Volume(_blob(), spacing=1.0, origin=(1e17, 0.0, 0.0))
    edge = clwave.Volume(_blob(), spacing=0.5, origin=(0.0, -ORIGIN_VOXELS * 0.5, 0.0))
    clwave.WaveletVolume.from_volume(edge, levels=1).save(tmp_path / "edge.clw")
    assert clwave.WaveletVolume.open(tmp_path / "edge.clw").origin == edge.origin

    import nibabel as nib

    affine = np.eye(4)
    affine[:3, 3] = 1e17
    nib.save(nib.Nifti1Image(_blob(), affine), tmp_path / "far.nii")
    header = (b"NRRD0004\ntype: float\ndimension: 3\nsizes: 12 12 12\nencoding: raw\nendian: little\n"
              b"space: left-posterior-superior\nspace directions: (1,0,0) (0,1,0) (0,0,1)\n"
              b"space origin: (1e17,1e17,1e17)\n\n")
    (tmp_path / "far.nrrd").write_bytes(header + _blob().astype("<f4").tobytes())
    for name in ("far.nii", "far.nrrd"):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with pytest.raises(InputError, match=r"more than 1e\+12 voxels from 0") as caught:
                clwave.load(tmp_path / name)
        assert "\n" not in str(caught.value)
        for argv in (["info"], ["render", "-o", str(tmp_path / "a.png")])[name == "far.nrrd":]:
            code, out, err = run(capsys, *argv[:1], str(tmp_path / name), *argv[1:])
            assert code == 2 and len(err.strip().splitlines()) == 1 and "clwave.load(path, origin=" in err, err
        assert not (tmp_path / "a.png").exists()

    def moved(header):
        header["origin"] = [1e17, 1e17, 1e17]

    with pytest.raises(FileFormatError, match=r"more than 1e\+12 voxels from 0"):
        clwave.WaveletVolume.open(crafted(tmp_path / "edge.clw", tmp_path, moved))
