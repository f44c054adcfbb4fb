"""Defects left by the twenty-second session's fuzzing and review (mend28; docs/known-gaps.md §15): each pinned by a
test that failed before its fix."""

import re
import struct
import warnings

import numpy as np
import pytest

import clwave
from clwave.errors import FileFormatError, InputError
from clwave.model.volume import ORIGIN_VOXELS
from test_cli import run
from test_hardening import crafted
from test_loaders import write_series


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
        for argv in (["info"], ["render", "-o", str(tmp_path / "a.png")]):
            code, out, err = run(capsys, *argv[:1], str(tmp_path / name), *argv[1:])
            assert code == 2 and len(err.strip().splitlines()) == 1 and "clwave.load(path, origin=" in err, err
        assert not (tmp_path / "a.png").exists()

    def moved(header):
        header["origin"] = [1e17, 1e17, 1e17]

    with pytest.raises(FileFormatError, match=r"more than 1e\+12 voxels from 0"):
        clwave.WaveletVolume.open(crafted(tmp_path / "edge.clw", tmp_path, moved))


NRRD_HEAD = {"type": "short", "dimension": "3", "sizes": "8 7 6", "encoding": "raw", "endian": "little",
             "space": "left-posterior-superior", "space directions": "(1,0,0) (0,1,0) (0,0,1)"}


@pytest.mark.parametrize("fields, words", [
    ({"dimension": "0"}, r"its header's dimension 0 is not the number of its sizes"),
    ({"encoding": "zstd"}, r"its encoding zstd is not one the NRRD reader \(pynrrd\) reads"),
    ({"type": "block"}, r"its type block is not one the NRRD reader"),
    ({"sizes": "8 7 1"}, r"declares 1 x 7 x 8 voxels \(112 bytes\) but the file holds 672 bytes"),
    ({"line skip": "2"}, r"declares 6 x 7 x 8 voxels \(672 bytes\) but the file holds 670 bytes"),
    ({"data file": "v.raw"}, r"names the data file v.raw, which is not beside it"),
    ({"space origin": "(1e17,0,0)"}, r"lies more than 1e\+12 voxels from 0"),
])
def test_info_refuses_the_nrrd_headers_a_read_refuses(tmp_path, capsys, fields, words):
    """NRRD headers that `clwave info` described (exit 0, its spacing "found with the voxels") and `load` refused
    (pynrrd's errors, or the volume's place): found by mutating one field (fuzz27, mend28's rerun); both refuse them
    now by the same check, before a voxel is read."""
    header = NRRD_HEAD | fields
    body = np.arange(336, dtype="<i2").tobytes()
    (tmp_path / "v.nrrd").write_bytes(("NRRD0004\n" + "".join(f"{k}: {v}\n" for k, v in header.items()) + "\n")
                                      .encode() + (b"\n" * 30 + body[30:] if "line skip" in fields else body))
    _refused_alike(capsys, tmp_path / "v.nrrd", words)


def _refused_alike(capsys, path, words):
    """``load`` and ``clwave info`` refuse ``path`` in one line matching ``words``, and ``clwave render`` too."""
    with pytest.raises((FileFormatError, InputError), match=words) as caught:
        clwave.load(path, progress_bar=False)
    assert "\n" not in str(caught.value)
    for argv in (["info"], ["render", "-o", str(path.parent / "a.png")]):
        code, out, err = run(capsys, *argv[:1], str(path), *argv[1:])
        assert code == 2 and len(err.strip().splitlines()) == 1 and not out, err
        assert re.search(words, err), err


@pytest.mark.parametrize("tag, value, words", [
    (259, 50000, r"tifffile cannot decode its pages \(ZSTD compression, 16-bit samples\)"),
    (258, 12, r"tifffile cannot decode its pages \(NONE compression, 12-bit samples\)"),
])
def test_info_refuses_the_tiff_pages_a_read_cannot_decode(tmp_path, capsys, tag, value, words):
    """A stack whose compression (ZSTD: Python's own module, absent before 3.14) or sample size (12 bits) tifffile
    cannot decode without imagecodecs: `clwave info` described it and a read failed on the voxels ("No module named
    'compression'", "packints_decode ... requires imagecodecs"); both refuse it by a trial decode of its first
    strip."""
    import importlib.util
    import tifffile

    if importlib.util.find_spec("imagecodecs") is not None:
        pytest.skip("imagecodecs decodes these pages here")  # not a kernel test: the refusal needs a missing codec
    tifffile.imwrite(tmp_path / "v.tif", np.arange(336, dtype=np.uint16).reshape(6, 7, 8))
    with tifffile.TiffFile(tmp_path / "v.tif") as tif:
        where = tif.pages[0].tags[tag].valueoffset
    content = bytearray((tmp_path / "v.tif").read_bytes())
    struct.pack_into("<H", content, where, value)
    (tmp_path / "w.tif").write_bytes(bytes(content))
    _refused_alike(capsys, tmp_path / "w.tif", words)


@pytest.mark.parametrize("attributes, words", [
    (dict(Rows=0), r"declares Rows 0, Columns 5, BitsAllocated 16 and BitsStored 16, which no image has"),
    (dict(BitsStored=20), r"declares Rows 6, Columns 5, BitsAllocated 16 and BitsStored 20, which no image has"),
    (dict(rescale=(0, 0)), r"has RescaleSlope = 0\.0 and RescaleIntercept = 0\.0, which map every uint16 sample "
                             r"to 0 in float32"),
])
def test_info_refuses_the_dicom_headers_a_read_refuses(tmp_path, capsys, rng, attributes, words):
    """A slice of Rows 0 or BitsStored past BitsAllocated (pydicom's refusals when it decodes), or of RescaleSlope 0
    (clwave's, as each slice was read): `clwave info` described the series; both refuse it from the headers now."""
    write_series(tmp_path, rng, [(0.0, 0.0, float(z)) for z in range(3)], "1.2.3", ["a", "b", "c"])
    write_series(tmp_path, rng, [(0.0, 0.0, 1.0)], "1.2.3", ["b"], **attributes)
    _refused_alike(capsys, tmp_path, words)


def test_an_mrc_sampling_of_needle_voxels_is_refused_naming_its_cell_and_sampling(tmp_path, capsys):
    """An mx of 2^31 - 1 (fuzz27): voxels of 4.7e-9 by 2 by 0.5 Å, described by `clwave info` and refused by the
    footprint textures' size naming --omega-s, an option that has nothing to do with it. The header's cell and
    sampling are named, by load, info and render alike; a map 100 times uneven is read."""
    from test_mrc import _write

    stored = np.random.default_rng(0).random((6, 7, 8)).astype(np.float32)
    path = _write(tmp_path / "m.mrc", stored, mx=2 ** 31 - 1)
    _refused_alike(capsys, path, r"its cell \(10, 14, 3 Å\) over its sampling \(mx, my, mz = 2147483647, 7, 6\) gives "
                                 r"voxels of 4\.66e-09 x 2 x 0\.5 Å \(x, y, z\), more than 10000 times longer")
    uneven = clwave.load(_write(tmp_path / "n.mrc", stored, mx=800), progress_bar=False)
    assert uneven.spacing == pytest.approx((0.5, 2.0, 10 / 800))


def test_a_post_classified_scalar_of_values_about_1e_36_renders_as_at_1():
    """A scalar of values about 1e-36 under an auto window rendered empty, without a warning: its packed pool's step
    (range / 65535, about 1e-41) is subnormal, 0 in the kernels' fast float32 arithmetic. The step is at least
    float32's least normal number: unshaded, the image is the one at scale 1 within the packing's and the tolerance's
    error; the coarser packing (7 bits) is warned of, naming the fix, as its shading is off by up to 0.13."""
    data = 0.2 + _blob(16)  # float32's normal numbers at 1e-36 too (its tails subnormal would be other data)
    camera = clwave.Camera(30, 20, size=24)
    images = []
    for scale in (1.0, 1e-36):
        model = clwave.WaveletVolume.from_volume(clwave.Volume(data * np.float32(scale)), levels=2)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            images.append(clwave.raytrace(model, camera, transfer_function="grey", tolerance=1e-3, shading=False).image)
        small = [w for w in caught if "pack them in fewer than 16 bits" in str(w.message)]
        assert len(small) == (scale < 1) and (scale == 1 or "multiply the volume's values" in str(small[0].message))
    assert images[0][..., 3].max() > 0.2
    np.testing.assert_allclose(images[1], images[0], atol=2e-3)


def test_a_needle_models_texel_pool_is_weighed_before_its_textures_are_made(monkeypatch):
    """Spacing 1000:1:1 (review27): each footprint's pool holds a phase plane per texel a pixel spans (3,820 here, at
    32 pixels), and the splatter made 9 GB of textures in 31 s CPU before its pool was refused. The pool is weighed
    with the textures, before one is made, naming the options that bound it (more pixels: at 512 the same model is
    splatted, 6 GB; the ray tracer). Since needle30 its textures, box-filtered by a pixel of 3,820 texels, are
    refused before their pool, naming more pixels too."""
    from clwave.errors import DeviceMemoryError
    from clwave.splat import textures

    volume = clwave.Volume(_blob(16), spacing=(1000.0, 1.0, 1.0))
    model = clwave.WaveletVolume.from_volume(volume, levels=2)
    monkeypatch.setattr(textures, "thread_map", lambda *a: pytest.fail("the textures were made before the refusal"))
    with pytest.raises(DeviceMemoryError, match=r"the footprint textures of this view need [\d,]+ texels .* render "
                                                r"more pixels \(--size\)"):  # needle30's pixel filter widens them first
        clwave.splat(model, clwave.Camera(30, 20, size=32))


def test_every_reader_names_units_by_one_table(tmp_path):
    """xarray's coordinates, an ImageJ stack and an OME-Zarr image each had their own table of unit names (an ImageJ
    "micrometre" or an xarray "nanometers" was no known unit): `io.images.UNIT_NAMES` is the one table now."""
    import tifffile
    import xarray as xr

    data = np.zeros((3, 4, 5), np.float32)
    tifffile.imwrite(tmp_path / "s.tif", data, imagej=True, resolution=(2.0, 2.0),
                     metadata={"unit": "micrometre", "spacing": 0.5, "axes": "ZYX"})
    assert clwave.load(tmp_path / "s.tif").unit == "um"
    coords = {d: np.arange(n) * 0.5 for d, n in zip("zyx", data.shape)}
    array = xr.DataArray(data, dims=("z", "y", "x"), coords=coords)
    for d in "zyx":
        array[d].attrs["units"] = "nanometers"
    assert clwave.Volume(array).unit == "nm"


@pytest.mark.parametrize("chunks", [False, 4])
def test_a_clw_records_the_file_and_frame_it_was_made_from(tmp_path, capsys, chunks):
    """A .clw did not say which file, nor which time point of a series (load(frame=K)), it was made from: both
    writers (a model in memory, a chunked one) record the provenance the loader gives, `clwave info` shows it, and a
    file of before (no key) opens as of no known provenance; a header's that is not a file and frame is refused."""
    import nibabel as nib

    series = np.random.default_rng(1).random((6, 7, 8, 3)).astype(np.float32)
    nib.save(nib.Nifti1Image(series, np.eye(4)), tmp_path / "s.nii")
    volume = clwave.load(tmp_path / "s.nii", frame=1, chunks=chunks)
    assert volume.provenance == {"file": str(tmp_path / "s.nii"), "frame": 1}
    clwave.WaveletVolume.from_volume(volume, levels=1).save(tmp_path / "m.clw")
    assert clwave.WaveletVolume.open(tmp_path / "m.clw").provenance == volume.provenance
    code, out, err = run(capsys, "info", str(tmp_path / "m.clw"))
    assert code == 0 and f"from       {tmp_path / 's.nii'}, frame 1 (--frame)\n" in out, out
    old = crafted(tmp_path / "m.clw", tmp_path, lambda header: header.pop("provenance"))
    assert clwave.WaveletVolume.open(old).provenance is None
    code, out, err = run(capsys, "info", str(old))
    assert code == 0 and "\nfrom " not in out
    with pytest.raises(FileFormatError, match=r"provenance \{'file': 3, 'frame': 1\} is not"):
        clwave.WaveletVolume.open(crafted(tmp_path / "m.clw", tmp_path, lambda header: header.update(
            provenance={"file": 3, "frame": 1})))
