"""clwave.load: every format round-trips a small file written here, in RAS+ (z, y, x).

Expected arrays are built from the array written and its geometry by hand (flips
and transposes worked out per case) or by `place_in_ras`, which scatters each
voxel to the grid position of its world coordinate: neither uses the loader's
orientation code.
"""

import json
import warnings
from pathlib import Path

import nibabel as nib
import nrrd
import numpy as np
import pytest
import tifffile
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid

from clwave.errors import ClwaveError, ClwaveWarning, FileFormatError, InputError
from clwave.io.loaders import load

SHAPE_IJK = (5, 6, 7)


def place_in_ras(data_ijk, affine_ras):
    """Scatter voxels of an axis-aligned (i, j, k) array onto a (z, y, x) RAS grid.

    Each voxel goes to ``(world - world.min) / spacing`` along x, y, z, so the
    result is the array a RAS+ viewer shows, with no orientation library involved.
    """
    ijk = np.indices(data_ijk.shape[:3]).reshape(3, -1)
    xyz = affine_ras[:3, :3] @ ijk + affine_ras[:3, 3:]
    spacing_xyz = np.abs(affine_ras[:3, :3]).sum(axis=1)  # one non-zero per row
    index = np.rint((xyz - xyz.min(axis=1, keepdims=True)) / spacing_xyz[:, None]).astype(int)
    dims_zyx = tuple(index.max(axis=1)[::-1] + 1)
    out = np.zeros(dims_zyx + data_ijk.shape[3:], data_ijk.dtype)
    out[index[2], index[1], index[0]] = data_ijk.reshape((ijk.shape[1],) + data_ijk.shape[3:])
    return out


def assert_one_line_error(excinfo):
    assert isinstance(excinfo.value, ClwaveError)
    message = str(excinfo.value)
    assert message and "\n" not in message


@pytest.fixture
def data_ijk(rng):
    return rng.integers(0, 1000, SHAPE_IJK).astype(np.int16)


# --------------------------------------------------------------------------- .npy and .raw

def test_npy_round_trip_with_spacing(tmp_path, rng):
    arr = rng.random((5, 6, 7)).astype(np.float32)
    np.save(tmp_path / "v.npy", arr)
    vol = load(tmp_path / "v.npy", spacing=(2.0, 1.0, 0.5))
    np.testing.assert_array_equal(vol.data, arr)
    assert vol.spacing == (2.0, 1.0, 0.5)
    assert vol.origin == (0.0, 0.0, 0.0)
    assert load(str(tmp_path / "v.npy")).spacing == (1.0, 1.0, 1.0)


@pytest.mark.parametrize("shape", [(5, 6, 7), (5, 6, 7, 3)])
def test_raw_big_endian_round_trip(tmp_path, rng, shape):
    arr = rng.integers(0, 60000, shape).astype(np.uint16)
    arr.astype(">u2").tofile(tmp_path / "v.raw")
    vol = load(tmp_path / "v.raw", shape=shape, dtype="uint16", byte_order=">",
               spacing=(0.5, 0.25, 0.25))
    np.testing.assert_array_equal(vol.data, arr.astype(np.float32))
    assert vol.spacing == (0.5, 0.25, 0.25)


def test_raw_truncated_reports_byte_counts(tmp_path):
    np.zeros((5, 6, 7), np.uint16)[:2].tofile(tmp_path / "v.raw")
    with pytest.raises(FileFormatError) as excinfo:
        load(tmp_path / "v.raw", shape=(5, 6, 7), dtype="uint16")
    assert_one_line_error(excinfo)
    assert "420 bytes" in str(excinfo.value) and "168 bytes" in str(excinfo.value)


def test_raw_needs_shape_and_dtype(tmp_path):
    np.zeros(10, np.uint8).tofile(tmp_path / "v.raw")
    with pytest.raises(InputError) as excinfo:
        load(tmp_path / "v.raw")
    assert_one_line_error(excinfo)
    assert "shape=" in str(excinfo.value)


def test_raw_options_refused_for_other_formats(tmp_path):
    np.save(tmp_path / "v.npy", np.zeros((3, 3, 3)))
    with pytest.raises(InputError, match="shape"):
        load(tmp_path / "v.npy", shape=(3, 3, 3))


# --------------------------------------------------------------------------- NIfTI

@pytest.mark.parametrize("name", ["v.nii", "v.nii.gz"])
def test_nifti_las_affine_lands_in_ras(tmp_path, data_ijk, name):
    # i runs to the Left (2 mm), j Anterior (3 mm), k Superior (0.5 mm): LAS
    affine = np.array([[-2.0, 0, 0, 10], [0, 3, 0, -4], [0, 0, 0.5, 7], [0, 0, 0, 1]])
    nib.save(nib.Nifti1Image(data_ijk, affine), tmp_path / name)
    vol = load(tmp_path / name)
    expected = data_ijk[::-1, :, :].transpose(2, 1, 0)  # flip i to point Right, then (z, y, x)
    np.testing.assert_array_equal(vol.data, expected)
    np.testing.assert_array_equal(vol.data, place_in_ras(data_ijk, affine))
    # voxel (0, 0, 0) sits at x = 10, the right-most x: last column, first row, first slice
    assert vol.data[0, 0, -1] == data_ijk[0, 0, 0]
    assert vol.spacing == (0.5, 3.0, 2.0)
    # centre = affine @ (2, 2.5, 3)
    np.testing.assert_allclose(vol.origin, (6.0, 3.5, 8.5))


def test_nifti_permuted_affine_lands_in_ras(tmp_path, data_ijk):
    # i -> Superior (2 mm), j -> Left (3 mm), k -> Anterior (0.5 mm)
    affine = np.array([[0, -3.0, 0, 0], [0, 0, 0.5, 0], [2.0, 0, 0, 0], [0, 0, 0, 1]])
    nib.save(nib.Nifti1Image(data_ijk, affine), tmp_path / "p.nii.gz")
    vol = load(tmp_path / "p.nii.gz")
    # z = i, y = k, x = flipped j
    np.testing.assert_array_equal(vol.data, data_ijk[:, ::-1, :].transpose(0, 2, 1))
    np.testing.assert_array_equal(vol.data, place_in_ras(data_ijk, affine))
    assert vol.spacing == (2.0, 0.5, 3.0)


def _scaled_nifti(path, raw, slope, inter):
    """``raw`` int16 saved as NIfTI-1 with ``scl_slope``/``scl_inter`` (nibabel resets them on save: written into
    the header's bytes 112-119), gzipped for a ``.gz`` path."""
    import gzip

    plain = path.with_name("plain.nii")
    nib.save(nib.Nifti1Image(raw, np.eye(4)), plain)
    data = bytearray(plain.read_bytes())
    data[112:120] = np.array([slope, inter], "<f4").tobytes()
    path.write_bytes(gzip.compress(bytes(data)) if path.suffix == ".gz" else bytes(data))


@pytest.mark.parametrize("name", ["s.nii", "s.nii.gz"])
def test_scaled_integer_nifti_is_read_as_its_scaled_values(tmp_path, rng, monkeypatch, name):
    """Integers with scl_slope/scl_inter are scaled a slab at a time into float32 (nibabel scales a whole read in
    float64): every voxel is float32(raw * slope + inter) of the header's float32 slope and intercept, whole (several
    slabs and a short last one) and in chunks; a slope past float32's range is refused by the largest value of any
    slab."""
    from clwave.io.loaders import nifti

    raw = rng.integers(-2048, 3000, (6, 5, 7)).astype(np.int16)
    raw[0, 0, 6] = 32767  # the largest value in the last (short) slab
    _scaled_nifti(tmp_path / name, raw, 0.37, -1024.5)
    expected = (raw * np.float64(np.float32(0.37)) - 1024.5).astype(np.float32).transpose(2, 1, 0)
    monkeypatch.setattr(nifti._ScaledToFloat32, "SLAB_VOXELS", 2 * 6 * 5)  # slabs of 2 of the 7 slices
    for chunks in (False,) if name.endswith(".gz") else (False, 3):  # gzip: read whole only
        np.testing.assert_array_equal(np.asarray(load(tmp_path / name, chunks=chunks).data), expected)
    _scaled_nifti(tmp_path / name, raw, 1e35, 0.0)
    with pytest.raises(InputError, match=r"holds values up to 3\.28e\+39, beyond float32's range"):
        load(tmp_path / name)


def test_valid_files_that_are_no_volume_are_named_for_what_they_are(tmp_path):
    """A CIFTI-2 file (nibabel's row_major.dconn.nii, a 10x10 matrix on grayordinates) and an object-dtype .npy are
    valid files, not truncated or corrupt ones: the one line says what they are and that they are no volume."""
    from nibabel.testing import data_path

    np.save(tmp_path / "obj.npy", np.array([{"a": 1}, None, 3], dtype=object))
    for path, words in ((Path(data_path) / "row_major.dconn.nii", "is a CIFTI-2 file of shape (10, 10), not a volume "
                                                                   "clwave reads"),
                        (tmp_path / "obj.npy", "is a NumPy array of Python objects (object), not of numbers: not a "
                                               "volume clwave reads")):
        with pytest.raises(FileFormatError) as excinfo:
            load(path)
        assert_one_line_error(excinfo)
        assert words in str(excinfo.value) and "corrupt" not in str(excinfo.value)


def test_an_oblique_nifti_warning_is_a_clwave_warning_line(tmp_path, capsys):
    """The loaders' notes (an oblique volume shown in the closest canonical orientation) are ClwaveWarnings, which a
    pipeline catching warnings sees (they were log records), and the command line's `clwave: warning: ...` lines,
    once."""
    from clwave.cli import main

    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    affine = np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    nib.save(nib.Nifti1Image(np.ones((8, 8, 8), np.float32), affine), tmp_path / "obl.nii")
    assert main(["compress", str(tmp_path / "obl.nii"), "--levels", "1", "-o", str(tmp_path / "o.clw")]) == 0
    assert capsys.readouterr().err.count("clwave: warning: the volume is oblique by 30.00 degrees; it is shown in "
                                         "the closest canonical (RAS) orientation, its axes taken as the world's "
                                         "(recorded in a .clw: a cone beam's pose is relative to them)\n") == 1
    with pytest.warns(ClwaveWarning, match=r"^the volume is oblique by 30.00 degrees"):
        load(tmp_path / "obl.nii")


def test_nifti_rgb24_gives_three_channels(tmp_path, rng):
    rgb = rng.integers(0, 256, SHAPE_IJK + (3,)).astype(np.uint8)
    structured = np.zeros(SHAPE_IJK, dtype=[("R", "u1"), ("G", "u1"), ("B", "u1")])
    for c, name in enumerate("RGB"):
        structured[name] = rgb[..., c]
    nib.save(nib.Nifti1Image(structured, np.eye(4)), tmp_path / "rgb.nii")
    vol = load(tmp_path / "rgb.nii")
    assert vol.channels == 3
    np.testing.assert_array_equal(vol.data, rgb.transpose(2, 1, 0, 3))


def test_spacing_argument_overrides_file(tmp_path, data_ijk):
    nib.save(nib.Nifti1Image(data_ijk, np.diag([2.0, 3.0, 4.0, 1.0])), tmp_path / "v.nii")
    assert load(tmp_path / "v.nii", spacing=1.5).spacing == (1.5, 1.5, 1.5)


# --------------------------------------------------------------------------- NRRD

def test_nrrd_lps_space_directions_land_in_ras(tmp_path, data_ijk):
    # LPS: i -> Left (1.5 mm), j -> Inferior (2 mm), k -> Posterior (0.8 mm)
    directions = np.array([[1.5, 0, 0], [0, 0, -2.0], [0, 0.8, 0]])
    header = {"space": "left-posterior-superior", "space directions": directions,
              "space origin": np.array([5.0, 6.0, 7.0])}
    nrrd.write(str(tmp_path / "v.nrrd"), data_ijk, header)
    vol = load(tmp_path / "v.nrrd")
    # in RAS every axis is reversed: x = flipped i, y = flipped k, z = flipped j
    expected = data_ijk[::-1, ::-1, ::-1].transpose(1, 2, 0)
    np.testing.assert_array_equal(vol.data, expected)
    affine_ras = np.eye(4)
    affine_ras[:3, :3] = np.diag([-1, -1, 1]) @ directions.T
    affine_ras[:3, 3] = [-5.0, -6.0, 7.0]
    np.testing.assert_array_equal(vol.data, place_in_ras(data_ijk, affine_ras))
    assert vol.spacing == pytest.approx((2.0, 0.8, 1.5))
    np.testing.assert_allclose(vol.origin, affine_ras[:3, :3] @ [2, 2.5, 3] + affine_ras[:3, 3])


def test_nrrd_left_handed_space_is_not_mirrored(tmp_path, data_ijk):
    directions = np.diag([1.0, 2.0, 0.5])
    for space in ("3D-left-handed", "3D-right-handed"):
        nrrd.write(str(tmp_path / f"{space}.nrrd"), data_ijk, {"space": space, "space directions": directions,
                                                               "space origin": np.array([1.0, 2.0, 3.0])})
    left, right = load(tmp_path / "3D-left-handed.nrrd"), load(tmp_path / "3D-right-handed.nrrd")
    # left-handed coordinates read as RAS (as the right-handed file is) give the mirror image; with the third
    # axis reversed the object is itself again, turned: x and y kept
    affine_ras = np.eye(4)
    affine_ras[:3, :3] = np.diag([1, 1, -1]) @ directions.T
    affine_ras[:3, 3] = [1.0, 2.0, -3.0]
    np.testing.assert_array_equal(left.data, place_in_ras(data_ijk, affine_ras))
    np.testing.assert_array_equal(left.data, right.data[::-1])
    assert left.spacing == right.spacing == (0.5, 2.0, 1.0)
    np.testing.assert_allclose(left.origin, np.array(right.origin) * (1, 1, -1))


def test_nrrd_rgb_axis_becomes_channels(tmp_path, rng):
    rgb_cijk = rng.integers(0, 256, (3,) + SHAPE_IJK).astype(np.uint8)
    header = {"space": "right-anterior-superior",
              "kinds": ["RGB-color", "domain", "domain", "domain"],
              "space directions": np.array([[np.nan] * 3, [1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]])}
    nrrd.write(str(tmp_path / "rgb.nrrd"), rgb_cijk, header)
    vol = load(tmp_path / "rgb.nrrd")
    np.testing.assert_array_equal(vol.data, rgb_cijk.transpose(3, 2, 1, 0))


def test_nrrd_unknown_spacing_is_taken_as_one_and_said(tmp_path, data_ijk):
    """NRRD's ``spacings: nan`` is "unknown": 1 on that axis, with a warning naming spacing= (none when given)."""
    nrrd.write(str(tmp_path / "v.nrrd"), data_ijk, {"spacings": [np.nan, 2.0, 3.0]})
    assert "spacings: nan 2 3" in (tmp_path / "v.nrrd").read_bytes().decode("latin-1")
    with pytest.warns(ClwaveWarning) as told:
        vol = load(tmp_path / "v.nrrd")
    assert vol.spacing == (3.0, 2.0, 1.0)  # (z, y, x): the file's x axis unknown
    [record] = told
    assert "spacing (dz, dy, dx) 3.0, 2.0, nan is unknown (nan) on some axes; taken as 1 there" in str(record.message)
    assert "--spacing DZ,DY,DX" in str(record.message)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert load(tmp_path / "v.nrrd", spacing=(3.0, 2.0, 0.5)).spacing == (3.0, 2.0, 0.5)


# --------------------------------------------------------------------------- TIFF

def test_tiff_stack_round_trip(tmp_path, rng):
    arr = rng.integers(0, 60000, (5, 6, 7)).astype(np.uint16)
    tifffile.imwrite(tmp_path / "v.tif", arr, photometric="minisblack")
    vol = load(tmp_path / "v.tif")
    np.testing.assert_array_equal(vol.data, arr)
    assert vol.spacing == (1.0, 1.0, 1.0)


def test_imagej_tiff_spacing_is_read(tmp_path, rng):
    arr = rng.integers(0, 60000, (5, 6, 7)).astype(np.uint16)
    # 4 pixels per micron along x, 2 along y, slices 2 microns apart: voxels of 2 x 0.5 x 0.25 (z, y, x)
    tifffile.imwrite(tmp_path / "ij.tif", arr, imagej=True, resolution=(4.0, 2.0),
                     metadata={"axes": "ZYX", "spacing": 2.0, "unit": "um"})
    vol = load(tmp_path / "ij.tif")
    np.testing.assert_array_equal(vol.data, arr)
    assert vol.spacing == (2.0, 0.5, 0.25) and vol.unit == "um"
    tifffile.imwrite(tmp_path / "nm.tif", arr, imagej=True, resolution=(4.0, 2.0),  # electron microscopy's unit
                     metadata={"axes": "ZYX", "spacing": 2.0, "unit": "nm"})
    assert load(tmp_path / "nm.tif").unit == "nm"
    assert load(tmp_path / "ij.tif", spacing=1.0).spacing == (1.0, 1.0, 1.0)
    # a plain TIFF's resolution is a print density (dots per inch), not a voxel size: spacing 1
    tifffile.imwrite(tmp_path / "plain.tif", arr, photometric="minisblack", resolution=(72.0, 72.0),
                     resolutionunit="INCH")
    assert load(tmp_path / "plain.tif").spacing == (1.0, 1.0, 1.0)
    # a bad z spacing (ImageJ writes what it is given) is 1 along z alone, with a warning; y and x stay
    tifffile.imwrite(tmp_path / "ij0.tif", arr, imagej=True, resolution=(4.0, 2.0),
                     metadata={"axes": "ZYX", "spacing": -2.0, "unit": "um"})
    assert load(tmp_path / "ij0.tif").spacing == (1.0, 0.5, 0.25)


def test_ome_tiff_spacing_is_read_in_micrometres(tmp_path, rng):
    arr = rng.integers(0, 60000, (5, 6, 7)).astype(np.uint16)
    # x in micrometres (OME's default unit), y in nanometres, z in millimetres: (2000, 0.25, 0.5) micrometres
    tifffile.imwrite(tmp_path / "v.ome.tif", arr, ome=True,
                     metadata={"axes": "ZYX", "PhysicalSizeX": 0.5, "PhysicalSizeY": 250.0, "PhysicalSizeYUnit": "nm",
                               "PhysicalSizeZ": 2.0, "PhysicalSizeZUnit": "mm"})
    vol = load(tmp_path / "v.ome.tif")
    np.testing.assert_array_equal(vol.data, arr)
    assert vol.spacing == pytest.approx((2000.0, 0.25, 0.5))
    assert load(tmp_path / "v.ome.tif", spacing=1.0).spacing == (1.0, 1.0, 1.0)
    # a size in a unit that is no length (OME allows only lengths; a file may still say anything) is 1 there alone,
    # with a warning naming the axis; a missing size is 1
    tifffile.imwrite(tmp_path / "odd.ome.tif", arr, ome=True,
                     metadata={"axes": "ZYX", "PhysicalSizeX": 0.5, "PhysicalSizeY": 3.0, "PhysicalSizeYUnit": "s"})
    with pytest.warns(ClwaveWarning) as told:
        assert load(tmp_path / "odd.ome.tif").spacing == pytest.approx((1.0, 1.0, 0.5))
    [said] = [str(w.message) for w in told]
    assert "along y" in said and "--spacing" in said and "along z" not in said


def _ome_pair(tmp_path, arr, spacing, first=None, tiff_units=None):
    """The same (z, y, x) volume as an OME-TIFF (tifffile: PhysicalSize, and its planes' positions of ``first``,
    the first voxel's (x, y, z), in ``tiff_units``) and as an OME-Zarr (scale and translation, micrometres)."""
    import zarr

    planes = {}
    if first is not None:
        units = tiff_units or {}
        scale = {axis: 1.0 / {"nm": 1e-3, "mm": 1e3}.get(units.get(axis), 1.0) for axis in "XYZ"}
        planes = dict(PositionX=[first[0] * scale["X"]] * len(arr), PositionY=[first[1] * scale["Y"]] * len(arr),
                      PositionZ=[(first[2] + spacing[0] * z) * scale["Z"] for z in range(len(arr))],
                      **{f"Position{axis}Unit": [unit] * len(arr) for axis, unit in units.items()})
    tifffile.imwrite(tmp_path / "v.ome.tif", arr, ome=True, metadata=dict(
        axes="ZYX", PhysicalSizeZ=spacing[0], PhysicalSizeY=spacing[1], PhysicalSizeX=spacing[2],
        **({"Plane": planes} if planes else {})))
    group = zarr.open_group(tmp_path / "v.zarr", mode="w", zarr_format=2)
    group.create_array("0", data=arr, chunks=arr.shape)
    transforms = [{"type": "scale", "scale": list(spacing)}]
    if first is not None:
        transforms.append({"type": "translation", "translation": list(first[::-1])})
    group.attrs["multiscales"] = [{"version": "0.4", "axes": [{"name": a, "type": "space", "unit": "micrometer"}
                                                              for a in "zyx"],
                                   "datasets": [{"path": "0", "coordinateTransformations": transforms}]}]
    return tmp_path / "v.ome.tif", tmp_path / "v.zarr"


@pytest.mark.parametrize("first, tiff_units", [(None, None), ((10.0, -20.0, 30.0), None),
                                               ((10.0, -20.0, 30.0), {"X": "nm", "Z": "mm"})])
def test_an_ome_tiff_and_an_ome_zarr_of_one_volume_are_placed_alike(tmp_path, rng, capsys, first, tiff_units):
    """The first voxel at the OME-TIFF's plane positions (each in its unit) or the OME-Zarr's translation, 0 where
    neither is given, and the origin the volume's centre (docs/coordinates.md §1): the same spacing and origin in
    the API and in clwave info (until tidy22 an OME-TIFF was centred at 0 whatever its positions)."""
    from clwave.cli import main

    arr = rng.integers(0, 60000, (5, 6, 7)).astype(np.uint16)
    spacing = (2.0, 0.25, 0.5)
    tif, zarr_store = _ome_pair(tmp_path, arr, spacing, first, tiff_units)
    corner = np.zeros(3) if first is None else np.array(first)
    want = corner + (np.array([7, 6, 5]) - 1) / 2 * np.array(spacing[::-1])  # the centre, (x, y, z)
    placed = []
    for path in (tif, zarr_store):
        vol = load(path)
        np.testing.assert_array_equal(np.asarray(vol.data), arr)
        assert vol.spacing == pytest.approx(spacing, rel=1e-12) and vol.unit == "um"
        np.testing.assert_allclose(vol.origin, want, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(vol.voxel_to_world(np.zeros((1, 3)))[0], corner, atol=1e-12)
        assert main(["info", str(path), "--json"]) == 0
        facts = json.loads(capsys.readouterr().out)
        placed.append((facts["spacing"], facts["origin"]))
        np.testing.assert_allclose(facts["origin"], vol.origin, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(placed[0], placed[1], rtol=1e-12, atol=1e-12)


def test_an_ome_tiff_position_that_is_no_length_is_0_with_a_warning(tmp_path, rng):
    arr = rng.integers(0, 60000, (3, 4, 5)).astype(np.uint16)
    tifffile.imwrite(tmp_path / "odd.ome.tif", arr, ome=True, metadata=dict(
        axes="ZYX", PhysicalSizeX=0.5, Plane=dict(PositionX=[4.0] * 3, PositionY=[8.0] * 3, PositionYUnit=["s"] * 3)))
    with pytest.warns(ClwaveWarning) as told:
        vol = load(tmp_path / "odd.ome.tif")
    np.testing.assert_allclose(vol.voxel_to_world(np.zeros((1, 3)))[0], (4.0, 0.0, 0.0))
    [said] = [str(w.message) for w in told]
    assert "plane position along y (8.0 's')" in said and "taken as 0 there" in said, said


def test_rgb_tiff_stack_is_4d(tmp_path, rng):
    arr = rng.integers(0, 256, (5, 6, 7, 3)).astype(np.uint8)
    tifffile.imwrite(tmp_path / "rgb.tiff", arr, photometric="rgb")
    vol = load(tmp_path / "rgb.tiff")
    assert vol.channels == 3
    np.testing.assert_array_equal(vol.data, arr)


def test_tiff_folder_stacks_in_natural_order(tmp_path, rng):
    slices = {n: rng.integers(0, 255, (6, 7)).astype(np.uint8) for n in range(1, 13)}
    for n in rng.permutation(list(slices)):  # creation order must not matter either
        tifffile.imwrite(tmp_path / f"slice{n}.tif", slices[n])
    (tmp_path / "notes.txt").write_text("not a slice")
    vol = load(tmp_path, spacing=(3.0, 1.0, 1.0))
    np.testing.assert_array_equal(vol.data, np.stack([slices[n] for n in range(1, 13)]))
    assert vol.spacing == (3.0, 1.0, 1.0)


@pytest.mark.parametrize("depth", [3, 4])
def test_a_small_stack_tifffile_wrote_as_planar_samples_is_a_volume(tmp_path, rng, depth):
    """``tifffile.imwrite`` of a 3 or 4 x Y x X array writes one RGB(A) page of planar samples; its own metadata
    says the array's shape, and it is read as that many slices, with a warning."""
    arr = rng.integers(0, 60000, (depth, 6, 7)).astype(np.uint16)
    with pytest.warns(DeprecationWarning):  # tifffile's own: "stored as RGB with separate component planes"
        tifffile.imwrite(tmp_path / "v.tif", arr)
    with tifffile.TiffFile(tmp_path / "v.tif") as tif:
        assert len(tif.pages) == 1 and tif.series[0].axes == "SYX"
    with pytest.warns(ClwaveWarning, match=f"read as {depth} slices"):
        vol = load(tmp_path / "v.tif")
    np.testing.assert_array_equal(vol.data, arr)
    assert vol.channels == 1


def test_one_tiff_image_is_refused_as_not_a_stack(tmp_path, rng):
    """A 2-D TIFF (grey, or RGB as pixels) is no volume: one line naming how to write one."""
    for name, arr, options in (("grey.tif", rng.integers(0, 255, (6, 7)).astype(np.uint8), {}),
                               ("rgb.tif", rng.integers(0, 255, (6, 7, 3)).astype(np.uint8), {"photometric": "rgb"})):
        tifffile.imwrite(tmp_path / name, arr, **options)
        with pytest.raises(FileFormatError, match="one 2-D image .* photometric='minisblack'") as excinfo:
            load(tmp_path / name)
        assert_one_line_error(excinfo)


def test_tiff_folder_of_planar_rgb_slices(tmp_path, rng):
    """In a folder each file is one 2-D slice: tifffile's planar RGB page of a 3 x Y x X array stays colour."""
    slices = rng.integers(0, 255, (4, 3, 6, 7)).astype(np.uint8)
    for z, planes in enumerate(slices):
        tifffile.imwrite(tmp_path / f"s{z}.tif", planes, photometric="rgb", planarconfig="separate")
    vol = load(tmp_path)
    np.testing.assert_array_equal(vol.data, slices.transpose(0, 2, 3, 1))


# --------------------------------------------------------------------------- DICOM

def write_dicom_slice(path, pixels, position, series_uid, *, orientation=(1, 0, 0, 0, 1, 0),
                      pixel_spacing=(0.7, 0.9), description="", number=1, rescale=(2, -1024), **attributes):
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = CTImageStorage
    meta.MediaStorageSOPInstanceUID = generate_uid()
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = Dataset()
    ds.file_meta = meta
    ds.SOPClassUID, ds.SOPInstanceUID = CTImageStorage, meta.MediaStorageSOPInstanceUID
    ds.Modality = "CT"
    ds.SeriesInstanceUID, ds.SeriesDescription, ds.SeriesNumber = series_uid, description, number
    ds.ImagePositionPatient = [float(p) for p in position]
    ds.ImageOrientationPatient = [float(c) for c in orientation]
    ds.PixelSpacing = list(pixel_spacing)
    ds.RescaleSlope, ds.RescaleIntercept = rescale
    ds.Rows, ds.Columns = pixels.shape
    ds.SamplesPerPixel, ds.PhotometricInterpretation = 1, "MONOCHROME2"
    ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 16, 16, 15, 0
    ds.PixelData = pixels.astype(np.uint16).tobytes()
    for name, value in attributes.items():
        setattr(ds, name, value)
    ds.save_as(path, enforce_file_format=True)


def write_series(folder, rng, positions, series_uid, names, **kwargs):
    """Write one 6 x 5 slice per ImagePositionPatient; returns the stored pixels in file order."""
    stored = rng.integers(0, 2000, (len(positions), 6, 5))
    for pixels, position, name in zip(stored, positions, names):
        write_dicom_slice(folder / name, pixels, position, series_uid, **kwargs)
    return stored


def axial(*z_positions):
    return [(-20.0, 30.0, z) for z in z_positions]


def test_dicom_series_sorted_rescaled_in_ras(tmp_path, rng):
    z_positions = [15.0, 10.0, 17.5, 12.5]  # written out of order, under shuffled names
    stored = write_series(tmp_path, rng, axial(*z_positions), generate_uid(),
                          ["b7", "a3", "IMG0001", "z"])
    (tmp_path / "README.txt").write_text("not DICOM")
    vol = load(tmp_path, progress_bar=False)

    hu = stored[np.argsort(z_positions)] * 2.0 - 1024  # slope 2, intercept -1024
    # the row index grows Posterior, the column index Left (LPS +y, +x): RAS flips both
    np.testing.assert_array_equal(vol.data, hu[:, ::-1, ::-1])
    assert vol.spacing == pytest.approx((2.5, 0.7, 0.9))  # slice gap, row, column spacing
    # centre in RAS: x = -(-20 + 0.9 * 2), y = -(30 + 0.7 * 2.5), z = (10 + 17.5) / 2
    np.testing.assert_allclose(vol.origin, (18.2, -31.75, 13.75))


@pytest.mark.parametrize("attributes, padded", [
    (dict(PixelPaddingValue=0), lambda stored: stored == 0),
    (dict(PixelPaddingValue=3, PixelPaddingRangeLimit=0), lambda stored: stored <= 3),  # a range, either way round
    (dict(PixelPaddingValue=0, PixelPaddingRangeLimit=3), lambda stored: stored <= 3),
], ids=["value", "range-down", "range-up"])
def test_dicom_padding_is_the_series_least_other_value(tmp_path, rng, capsys, attributes, padded):
    """PixelPaddingValue (and PixelPaddingRangeLimit) mark stored values outside the patient (PS3.3 C.7.5.1.1.2):
    they become the least other value of the whole series after the rescale (air in a CT), not the rescaled padding
    (-1024 HU here, -3024 HU in a scanner's), which an X-ray would integrate as a dense shell."""
    stored = rng.integers(0, 8, (3, 6, 5))  # slices 0 and 1, and 2, hold padding; the least other value is in one
    stored[:, 0, :] = 0
    write_series_of(tmp_path, stored, axial(0.0, 1.0, 2.0), generate_uid(), **attributes)
    hu = stored * 2.0 - 1024
    hu[padded(stored)] = hu[~padded(stored)].min()
    with pytest.warns(ClwaveWarning, match=r"marks \d.* % of its voxels as padding .*least other value, -10"):
        vol = load(tmp_path, progress_bar=False)
    np.testing.assert_array_equal(vol.data, hu[:, ::-1, ::-1])
    stored[:] = 0  # every pixel padding: no image, refused in one line
    write_series_of(tmp_path, stored, axial(0.0, 1.0, 2.0), generate_uid(), number=2, **attributes)
    with pytest.raises(InputError):  # two series now: the second named
        load(tmp_path)
    with pytest.raises(FileFormatError, match="marks every pixel as padding") as excinfo:
        load(tmp_path, series=2, progress_bar=False)  # its SeriesNumber
    assert_one_line_error(excinfo)


def write_series_of(folder, stored, positions, series_uid, **kwargs):
    """Write the slices ``stored`` at ImagePositionPatient ``positions``, named by series and index."""
    for k, (pixels, position) in enumerate(zip(stored, positions)):
        write_dicom_slice(folder / f"{series_uid[-6:]}_{k}", pixels, position, series_uid, **kwargs)


@pytest.mark.parametrize("odd", [0, 2, 4])
def test_dicom_series_of_mixed_pixel_spacing_refused(tmp_path, rng, odd):
    """One slice of another PixelSpacing (first, in the middle, last) is named in one line, as mixed orientations
    are; the first slice's spacing was once used for all."""
    uid = generate_uid()
    for k, position in enumerate(axial(0.0, 1.0, 2.0, 3.0, 4.0)):
        write_dicom_slice(tmp_path / f"s{k}", rng.integers(0, 9, (6, 5)), position, uid,
                          pixel_spacing=(0.7, 0.8) if k == odd else (0.7, 0.9))
    with pytest.raises(FileFormatError) as excinfo:
        load(tmp_path, progress_bar=False)
    assert_one_line_error(excinfo)
    assert f"mixes pixel spacings: s{odd} has PixelSpacing 0.7, 0.8 mm where 4 of its 5 slices have 0.7, 0.9" in \
        str(excinfo.value)


def test_dicom_sagittal_series_lands_in_ras(tmp_path, rng):
    # the column index grows Posterior (+y in LPS), the row index Inferior (-z): the
    # normal is (0, 1, 0) x (0, 0, -1) = (-1, 0, 0), to the patient's Right
    x_positions = [1.0, 5.0, -1.0, 3.0]
    stored = write_series(tmp_path, rng, [(x, -10.0, 50.0) for x in x_positions], generate_uid(),
                          ["s1", "s2", "s3", "s4"], orientation=(0, 1, 0, 0, 0, -1),
                          pixel_spacing=(0.5, 0.25))
    vol = load(tmp_path)
    # slices sorted Left to Right (x = 5, 3, 1, -1 in LPS) become RAS x; flipped rows
    # (Inferior -> Superior) become z, flipped columns (Posterior -> Anterior) become y
    hu = stored[np.argsort(-np.array(x_positions))] * 2.0 - 1024
    np.testing.assert_array_equal(vol.data, hu[:, ::-1, ::-1].transpose(1, 2, 0))
    assert vol.spacing == pytest.approx((0.5, 0.25, 2.0))


def test_dicom_two_series_need_series_argument(tmp_path, rng, capsys):
    """Several series are listed as PACS viewers list them (number, description, modality, slices, size), and
    series= picks one by what the listing shows: its SeriesNumber, its description (case aside) or its UID."""
    uid_a, uid_b = generate_uid(), generate_uid()
    stored_a = write_series(tmp_path, rng, axial(0.0, 1.0, 2.0, 3.0), uid_a,
                            ["a1", "a2", "a3", "a4"], description="soft tissue", number=1)
    stored_b = write_series(tmp_path, rng, axial(0.0, 2.0, 4.0), uid_b, ["b1", "b2", "b3"],
                            description="bone", number=2)
    with pytest.raises(InputError) as excinfo:
        load(tmp_path)
    assert_one_line_error(excinfo)
    assert str(excinfo.value) == f"{tmp_path} holds 2 DICOM series: series 1 'soft tissue' (CT, 4 slices of 5 x 6); " \
        "series 2 'bone' (CT, 3 slices of 5 x 6); pick one with series=NUMBER as listed (or its description, or its " \
        "SeriesInstanceUID)"

    for series in (2, "2", "BONE", uid_b):
        picked = load(tmp_path, series=series)
        np.testing.assert_array_equal(picked.data, (stored_b * 2.0 - 1024)[:, ::-1, ::-1])
        assert picked.spacing[0] == pytest.approx(2.0)
    by_uid = load(tmp_path, series=uid_a)
    np.testing.assert_array_equal(by_uid.data, (stored_a * 2.0 - 1024)[:, ::-1, ::-1])
    with pytest.raises(InputError, match="series=0 matches none of the 2 DICOM series"):
        load(tmp_path, series=0)  # no longer a 0-based index
    # the command line says it with its own flag, and one slice file points to the series' folder
    from clwave.cli import main
    assert main(["compress", str(tmp_path), "-o", str(tmp_path / "out.clw")]) == 2
    err = capsys.readouterr().err
    assert "--series NUMBER" in err and "series=" not in err and err.count("\n") == 1
    for series, slices in (("2", 3), (uid_a, 4), ("soft tissue", 4)):  # info reads --series as compress does
        assert main(["info", str(tmp_path), "--series", series]) == 0
        assert f"stored     {slices} x 6 x 5 values" in capsys.readouterr().out
    (tmp_path / "a1").rename(tmp_path / "a1.dcm")
    assert main(["compress", str(tmp_path / "a1.dcm"), "-o", str(tmp_path / "out.clw")]) == 2
    assert "pass the folder" in capsys.readouterr().err


def test_dicom_duplicate_positions_refused(tmp_path, rng):
    write_series(tmp_path, rng, axial(0.0, 1.0, 1.0), generate_uid(), ["s1", "s2", "s3"])
    with pytest.raises(FileFormatError) as excinfo:
        load(tmp_path)
    assert_one_line_error(excinfo)
    assert "slice s2 and slice s3 of DICOM series" in str(excinfo.value)
    assert str(excinfo.value).endswith("share one position; the series may hold several acquisitions (echoes, phases, "
                                       "times): split them into separate folders")


def test_dicom_multi_frame_file_alone_in_a_folder_is_its_series(tmp_path):
    """A multi-frame DICOM file (pydicom's rtdose.dcm, 15 frames) alone in a folder is read as its series, as the file
    itself is, not refused as a series of 1 slice."""
    import shutil

    from pydicom.data import get_testdata_file

    shutil.copy(get_testdata_file("rtdose.dcm"), tmp_path / "rtdose.dcm")
    folder, file = load(tmp_path), load(tmp_path / "rtdose.dcm")
    np.testing.assert_array_equal(folder.data, file.data)
    assert folder.data.shape[0] == 15 and folder.spacing == file.spacing and folder.origin == file.origin


@pytest.mark.parametrize("kwargs, needle", [
    (dict(rescale=(0, -1024)), "RescaleSlope = 0.0 and RescaleIntercept = -1024.0, which map every uint16 sample to "
                               "-1024"),
    (dict(rescale=(float("nan"), 0)), "non-finite RescaleSlope"),
    (dict(rescale=(1, float("inf"))), "non-finite RescaleIntercept"),
    (dict(pixel_spacing=(float("nan"), 1.0)), "non-finite PixelSpacing"),
    (dict(orientation=(1, 0, 0, 0, float("inf"), 0)), "non-finite ImageOrientationPatient"),
    (dict(position=(float("nan"), 0.0, 2.0)), "non-finite ImagePositionPatient"),
    # found by fuzzing (harden20): overflow warnings beside the error, or an error naming something else
    (dict(rescale=(1e308, 0)), "RescaleSlope (1e+308) beyond float32's range"),
    (dict(pixel_spacing=(0.0, 0.0)), "PixelSpacing (0.0, 0.0) beyond the world lengths"),
    (dict(pixel_spacing=(1.0,)), "PixelSpacing (1.0) of 1 values, not 2"),
    (dict(orientation=(1, 0, 0, 1, 0, 0)), "not two perpendicular unit vectors"),
    (dict(orientation=(1e308, 0, 0, 0, 1e308, 0)), "not two perpendicular unit vectors"),
    (dict(position=(0.0, 0.0, 1e300)), "ImagePositionPatient (0.0, 0.0, 1e+300) beyond the world lengths"),
])
def test_dicom_degenerate_rescale_and_geometry_refused(tmp_path, rng, kwargs, needle):
    uid, position = generate_uid(), kwargs.pop("position", None)
    write_series(tmp_path, rng, axial(0.0, 1.0), uid, ["s1", "s2"])
    write_dicom_slice(tmp_path / "odd", np.full((6, 5), 8), position or axial(2.0)[0], uid, **kwargs)
    with pytest.raises(FileFormatError) as excinfo, warnings.catch_warnings():
        warnings.simplefilter("error")  # no Python warning beside the one line
        load(tmp_path, progress_bar=False)
    assert_one_line_error(excinfo)
    assert needle in str(excinfo.value) and "odd" in str(excinfo.value)


@pytest.mark.parametrize("drift, degrees, shift, shape", [
    ((0.0, 0.5), "26.6", "1.5", (4, 10, 6)),      # 0.5 mm further posterior (LPS +y) per mm along z
    ((-0.25, 0.5), "29.2", "1.677", (4, 10, 7)),  # and 0.25 mm further right (LPS -x): a margin before the first slice
])
def test_dicom_gantry_tilt_resampled_onto_a_straight_stack(tmp_path, monkeypatch, drift, degrees, shift, shape):
    """Slices shifted sideways in proportion to their distance along the normal: a gantry tilt.  They hold a linear
    function of the LPS position, which linear interpolation keeps exactly: every voxel of the straight stack that a
    slice covers holds that function at its own RAS position (from the volume's spacing and origin alone), and the
    margins the shift opens hold the series' least value."""
    uid, rows, columns, (a, b) = generate_uid(), 8, 6, drift
    j, i = np.mgrid[:rows, :columns]
    least = np.inf
    for z in range(4):  # axial: a row runs along LPS x, a column along LPS y; pixels of 1 mm
        corner = np.array([-20.0 + a * z, 30.0 + b * z, z])
        lps = corner[:, None, None] + np.stack([i, j, np.zeros_like(i)])
        stored = np.round(4 * (3 * lps[0] - 2 * lps[1] + 4 * lps[2] + 500))  # whole numbers: the file's uint16
        least = min(least, 2 * stored.min() - 1024)  # rescale slope 2, intercept -1024
        write_dicom_slice(tmp_path / f"s{z}", stored, corner, uid, pixel_spacing=(1.0, 1.0))
    with pytest.warns(ClwaveWarning, match=f"gantry tilt of {degrees} degrees .*{shift} mm sideways over 3 mm"):
        vol = load(tmp_path)
    assert vol.data.shape == shape and vol.spacing == pytest.approx((1.0, 1.0, 1.0))
    n = np.array(vol.data.shape[::-1])
    kx, ky, kz = np.meshgrid(*(np.arange(m) for m in n), indexing="ij")
    ras = np.asarray(vol.origin)[:, None, None, None] + (np.stack([kx, ky, kz]) - (n[:, None, None, None] - 1) / 2)
    x, y, z = -ras[0], -ras[1], ras[2]  # LPS
    x0, y0 = -20.0 + a * z, 30.0 + b * z  # each slice's first pixel
    e = 1e-9
    covered = (x >= x0 - e) & (x <= x0 + columns - 1 + e) & (y >= y0 - e) & (y <= y0 + rows - 1 + e)
    value = vol.data.transpose(2, 1, 0)  # (x, y, z) like the grid above
    assert covered.sum() >= 4 * (rows - 1) * (columns - 1)
    np.testing.assert_allclose(value[covered], (2 * 4 * (3 * x - 2 * y + 4 * z + 500) - 1024)[covered], atol=1e-2)
    margin = (x < x0 - 1 + e) | (x > x0 + columns - e) | (y < y0 - 1 + e) | (y > y0 + rows - e)  # a pixel beyond
    assert margin.sum() > 0 and np.all(value[margin] == least) and value.min() == least
    from clwave.io.loaders import describe, dicom  # what info says of it: the straight stack, named so, unread
    monkeypatch.setattr(dicom, "_dicom_pixels", lambda path: pytest.fail(f"{path}'s pixels were read"))
    facts = describe(tmp_path)
    assert facts["stored_shape"] == list(shape) and facts["resampled"] and facts["dtype"] == "float32"
    assert facts["spacing"] == pytest.approx(vol.spacing) and facts["origin"] == pytest.approx(vol.origin)
    assert (facts["stored_dtype"], facts["rescale"], facts["padding"]) == ("uint16", [[2.0, -1024.0]], [])


def test_info_of_a_dicom_folder_reads_no_pixel(tmp_path, rng, monkeypatch, capsys):
    """The stack is weighed from the slices' headers (their rows and columns), before the first slice's pixels."""
    from clwave.cli import main
    from clwave.io.loaders import dicom

    uid = generate_uid()
    write_series(tmp_path, rng, axial(0.0, 1.0, 2.0), uid, ["s1", "s2", "s3"], PixelPaddingValue=0, number=4,
                 description="Thorax 1.0")
    vol = load(tmp_path)
    monkeypatch.setattr(dicom, "_dicom_pixels", lambda path: pytest.fail(f"{path}'s pixels were read"))
    assert main(["info", str(tmp_path)]) == 0
    # the series, the stored type, the place load gives it (spacing, RAS origin), the rescale and the padding, from
    # the headers
    assert capsys.readouterr().out.splitlines()[1:] == [
        f"series     series 4 'Thorax 1.0', CT, {uid}",
        "stored     3 x 6 x 5 values of float32, in the file's order of axes (stored as uint16)",
        "volume     5 x 6 x 3 voxels (x, y, z), 1 channel of float32",
        "spacing    0.9, 0.7, 1 mm (x, y, z; --spacing 1,0.7,0.9), centre 18.2, -31.75, 1, corner voxel (least x, y, "
        "z) 16.4, -33.5, 0 (RAS+)",
        "box        4.5, 4.2, 3 (x, y, z) mm",
        "rescale    slope 2, intercept -1024",
        "padding    stored 0 (outside the patient): set to the series' least other value when read"]
    assert vol.spacing == pytest.approx((1.0, 0.7, 0.9)) and vol.origin == pytest.approx((18.2, -31.75, 1.0))


def test_dicom_slices_off_any_line_refused(tmp_path, rng):
    # one slice 2 mm sideways of a straight stack (pixels of 0.7 and 0.9 mm): no tilt moves one slice alone
    positions = axial(0.0, 1.0, 2.0, 3.0, 4.0)
    positions[2] = (-18.0, 30.0, 2.0)
    write_series(tmp_path, rng, positions, generate_uid(), list("abcde"))
    with pytest.raises(FileFormatError) as excinfo:
        load(tmp_path)
    message = str(excinfo.value)
    assert "does not lie on a line" in message and "at 2 mm along the normal" in message and "\n" not in message


def test_dicom_positions_rounded_in_the_file_still_load(tmp_path, rng):
    # an oblique series (rotated 30 degrees about z) whose positions are written to 2 decimals: strays far below
    # a tenth of a pixel sideways and of a slice along the normal
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    normal = np.cross((c, s, 0), (-s, c, 0))
    positions = [np.round(np.array([-20.0, 30.0, 0.0]) + 0.625 * k * normal, 2) for k in range(5)]
    write_series(tmp_path, rng, positions, generate_uid(), list("abcde"), orientation=(c, s, 0, -s, c, 0))
    assert load(tmp_path).spacing[0] == pytest.approx(0.625, abs=0.01)


@pytest.mark.parametrize("decimals, pixel, gap", [(1, 0.5, 1.0), (1, 0.9, 3.0), (2, 0.15, 0.5)])
def test_a_double_oblique_series_rounded_in_the_file_loads(tmp_path, rng, decimals, pixel, gap):
    """Its normal 20 degrees off z, positions written to a decimal or two: their rounding scatters about a straight,
    even stack (as far as a tenth of a pixel sideways, of a slice along the normal) and is no tilt or gap; the
    fitted drift and grid are what the checks weigh."""
    t = np.radians(20)
    row, col = np.array([1.0, 0.0, 0.0]), np.array([0.0, np.cos(t), np.sin(t)])
    positions = [np.round(np.array([-100.0, 37.3, 12.1]) + gap * k * np.cross(row, col), decimals) for k in range(40)]
    write_series(tmp_path, rng, positions, generate_uid(), [f"s{k:02d}" for k in range(40)], orientation=(*row, *col),
                 pixel_spacing=(pixel, pixel))
    assert load(tmp_path).spacing == pytest.approx((gap, pixel, pixel), rel=1e-3)


@pytest.mark.parametrize("z, needle", [
    ((0.0, 1.0, 2.0, 3.0, 8.0, 9.0), "slices at 3 and 8 mm along the normal are 5 mm apart, more than 4 times its "
                                     "smallest gap (1 mm), more than 3 missing slices"),
    ((0.0, 0.5, 6.0, 11.0), "are 5.5 mm apart, more than 4 times its smallest gap (0.5 mm)"),
])
def test_dicom_gap_of_more_than_missing_slices_refused(tmp_path, rng, z, needle):
    """A gap of more than 4 of the smallest is no missing slice but another acquisition (docs/coordinates.md §1);
    smaller ones are resampled (test_dicom_geometry.py)."""
    write_series(tmp_path, rng, axial(*z), generate_uid(), [f"s{i}" for i in range(len(z))])
    with pytest.raises(FileFormatError) as excinfo:
        load(tmp_path)
    message = str(excinfo.value)
    assert needle in message and "supply the complete series, or split its acquisitions" in message
    assert "\n" not in message


# --------------------------------------------------------------------------- bad input

def _truncate(path):
    raw = path.read_bytes()
    path.write_bytes(raw[: len(raw) // 2])
    return path


def _unknown(tmp_path):
    (tmp_path / "v.xyz").write_bytes(b"1234")
    return tmp_path / "v.xyz"


def _empty_folder(tmp_path):
    (tmp_path / "empty").mkdir()
    return tmp_path / "empty"


def _cut_nifti(tmp_path):
    data = np.arange(40 * 40 * 40, dtype=np.float32).reshape(40, 40, 40)
    nib.save(nib.Nifti1Image(data, np.eye(4)), tmp_path / "v.nii.gz")
    return _truncate(tmp_path / "v.nii.gz")


def _cut_nrrd(tmp_path):
    data = np.arange(20 * 20 * 20, dtype=np.int32).reshape(20, 20, 20)
    nrrd.write(str(tmp_path / "v.nrrd"), data)
    return _truncate(tmp_path / "v.nrrd")


def _cut_tiff(tmp_path):
    tifffile.imwrite(tmp_path / "v.tif", np.ones((5, 30, 30), np.uint16), photometric="minisblack")
    return _truncate(tmp_path / "v.tif")


def _cut_dicom(tmp_path):
    write_series(tmp_path, np.random.default_rng(1), axial(0.0, 1.0, 2.0), generate_uid(),
                 ["s1", "s2", "s3"])
    _truncate(tmp_path / "s2")
    return tmp_path


def _nan_npy(tmp_path):
    arr = np.zeros((5, 6, 7), np.float32)
    arr[2, 3, 4] = np.nan
    np.save(tmp_path / "nan.npy", arr)
    return tmp_path / "nan.npy"


@pytest.mark.parametrize("make, error", [
    (_unknown, FileFormatError),
    (lambda tmp_path: tmp_path / "missing.nii", FileFormatError),
    (_empty_folder, FileFormatError),
    (_cut_nifti, FileFormatError),
    (_cut_nrrd, FileFormatError),
    (_cut_tiff, FileFormatError),
    (_cut_dicom, FileFormatError),
    (_nan_npy, InputError),
], ids=["unknown-extension", "missing", "empty-folder", "cut-nii.gz", "cut-nrrd", "cut-tif",
        "cut-dicom", "nan-npy"])
def test_bad_input_gives_one_line_error(tmp_path, make, error):
    with pytest.raises(error) as excinfo:
        load(make(tmp_path))
    assert_one_line_error(excinfo)


def test_unknown_extension_names_supported_formats(tmp_path):
    with pytest.raises(FileFormatError, match=r"\.nii\.gz.*\.nrrd.*DICOM"):
        load(_unknown(tmp_path))


# --------------------------------------------------------------------------- CT units

def test_hu_to_mu_and_subtract(tmp_path):
    hu = np.full((3, 3, 3), -1000.0, np.float32)
    hu[1, 1, 1], hu[0, 0, 0], hu[2, 2, 2] = 0.0, 1000.0, -3024.0
    np.save(tmp_path / "ct.npy", hu)
    mu_water = 0.02
    vol = load(tmp_path / "ct.npy", hu_to_mu=True, mu_water=mu_water)
    assert vol.data[0, 1, 0] == 0.0  # air
    assert vol.data[2, 2, 2] == 0.0  # below air: clipped
    assert vol.data[1, 1, 1] == pytest.approx(mu_water, rel=1e-6)
    assert vol.data[0, 0, 0] == pytest.approx(2 * mu_water, rel=1e-6)

    expected_mu = np.maximum(mu_water * (1 + hu / 1000), 0)
    np.testing.assert_allclose(vol.data, expected_mu, rtol=1e-6, atol=0)
    shifted = load(tmp_path / "ct.npy", hu_to_mu=True, mu_water=mu_water, subtract=0.005)
    np.testing.assert_allclose(shifted.data, expected_mu - 0.005, rtol=0, atol=1e-7)
    raw = load(tmp_path / "ct.npy", subtract=-1000)
    np.testing.assert_array_equal(raw.data, hu + 1000)


# --------------------------------------------------------------------------- declared sizes


def _zeros_nii_gz(path):
    nib.save(nib.Nifti1Image(np.zeros((64, 64, 64), np.uint8), np.eye(4)), path)
    return nib.arrayproxy.ArrayProxy, "__getitem__"


def _zeros_nrrd_gzip(path):
    nrrd.write(str(path), np.zeros((64, 64, 64), np.uint8), {"encoding": "gzip"})
    from clwave.io.loaders import nrrd as reader
    return reader, "_inflated"


def _zeros_tiff_zlib(path):
    tifffile.imwrite(path, np.zeros((64, 64, 64), np.uint8), photometric="minisblack", compression="zlib")
    return tifffile.TiffPageSeries, "asarray"


def _zeros_npy(path):
    np.lib.format.open_memmap(path, "w+", np.uint8, (64, 64, 64)).flush()  # a sparse file
    from clwave.io.loaders import raw
    return raw, "read_memmap"


@pytest.mark.parametrize("write, name", [(_zeros_nii_gz, "v.nii.gz"), (_zeros_nrrd_gzip, "v.nrrd"),
                                         (_zeros_tiff_zlib, "v.tif"), (_zeros_npy, "v.npy")])
def test_a_declared_size_is_weighed_before_the_data_are_read(tmp_path, monkeypatch, write, name):
    """The shape and type a header declares are weighed before the data are read: by ``fits`` (the command
    line's rule for the model), then by what reading the volume whole takes (its samples, and float32)."""
    import clwave.device.memory
    from clwave.device.memory import HostMemoryError

    path = tmp_path / name
    owner, reader = write(path)
    reads = []
    monkeypatch.setattr(owner, reader, lambda *args, **kwargs: reads.append(args))

    class Refused(ClwaveError):
        pass

    declared = []

    def fits(voxels, channels):
        declared.append((voxels, channels))
        raise Refused("refused")

    with pytest.raises(Refused):
        load(path, fits=fits)
    assert declared == [(64 ** 3, 1)] and not reads
    monkeypatch.setattr(clwave.device.memory, "available_bytes", lambda: 64 ** 3 * 5 - 1)  # uint8 + float32
    with pytest.raises(HostMemoryError, match=f"reading .*{name} whole \\(64 x 64 x 64 uint8\\)") as excinfo:
        load(path)
    assert isinstance(excinfo.value, MemoryError) and "\n" not in str(excinfo.value) and not reads


def test_a_raw_file_is_weighed_before_it_is_read(tmp_path, monkeypatch):
    import clwave.device.memory
    from clwave.device.memory import HostMemoryError
    from clwave.io.loaders import raw

    path = tmp_path / "v.raw"
    with open(path, "wb") as fh:
        fh.truncate(64 ** 3 * 2)  # sparse
    monkeypatch.setattr(raw, "read_memmap", lambda *args: pytest.fail("read"))
    monkeypatch.setattr(clwave.device.memory, "available_bytes", lambda: 64 ** 3 * 6 - 1)  # int16 + float32
    with pytest.raises(HostMemoryError, match="64 x 64 x 64 int16"):
        load(path, shape=(64, 64, 64), dtype="int16")


def test_float32_is_weighed_as_read(tmp_path, monkeypatch):
    """float32 samples are used as they are read: 4 bytes a value, no second copy (int16: 2 + 4)."""
    import clwave.device.memory

    np.save(tmp_path / "f.npy", np.ones((32, 32, 32), np.float32))
    np.save(tmp_path / "i.npy", np.ones((32, 32, 32), np.int16))
    monkeypatch.setattr(clwave.device.memory, "available_bytes", lambda: 32 ** 3 * 5)
    assert load(tmp_path / "f.npy").data.sum() == 32 ** 3
    with pytest.raises(MemoryError, match="32 x 32 x 32 int16"):
        load(tmp_path / "i.npy")


def test_a_stack_of_slices_is_weighed_after_its_first_slice(tmp_path, monkeypatch):
    """A folder of slices declares its size by its first slice and its number of files: weighed before the rest."""
    from clwave.io.loaders import slices

    for z in range(8):
        tifffile.imwrite(tmp_path / f"s{z}.tif", np.zeros((16, 16), np.uint16))
    read, declared = [], []
    real = slices.read_tiff
    monkeypatch.setattr(slices, "read_tiff", lambda path, **kwargs: read.append(path) or real(path, **kwargs))

    class Refused(ClwaveError):
        pass

    def fits(voxels, channels):
        declared.append((voxels, channels))
        raise Refused("refused")

    with pytest.raises(Refused):
        load(tmp_path, fits=fits)
    assert declared == [(8 * 16 * 16, 1)] and [p.name for p in read] == ["s0.tif"]


def test_a_scaled_vector_nifti_is_scaled_a_slab_of_z_at_a_time(tmp_path, rng, monkeypatch):
    """A vector NIfTI (x, y, z, 1, channels) of scaled integers: slabs of z within every channel, as the bound says
    (the last axis would be a whole channel volume a slab), and the values those of the scalar case."""
    import nibabel.volumeutils

    from clwave.io.loaders import nifti

    raw = rng.integers(-2048, 3000, (6, 5, 7, 1, 3)).astype(np.int16)
    _scaled_nifti(tmp_path / "v.nii", raw, 0.37, -1024.5)
    slabs, scale = [], nibabel.volumeutils.apply_read_scaling
    monkeypatch.setattr(nibabel.volumeutils, "apply_read_scaling", lambda a, *k: slabs.append(a.size) or scale(a, *k))
    monkeypatch.setattr(nifti._ScaledToFloat32, "SLAB_VOXELS", 2 * 6 * 5 * 3)  # slabs of 2 of the 7 slices
    got = np.asarray(load(tmp_path / "v.nii").data)
    expected = (raw[:, :, :, 0] * np.float64(np.float32(0.37)) - 1024.5).astype(np.float32)  # x, y, z, channels
    np.testing.assert_array_equal(got, expected.transpose(2, 1, 0, 3))
    assert slabs and max(slabs) <= 2 * 6 * 5 * 3, slabs
