"""A stack with no orientation of its own given one (orientation=, --orientation), its unit (unit=, --unit) and
its place (origin=), and the spacing `clwave info` prints as the `--spacing` that gives it (trial25 M2, M4, P3).

Expected arrays come from the array written and the orientation's meaning worked out by hand (`place_in_ras`
scatters each voxel to its world position) or from the DICOM loader's reading of the same pixels, never from the
orientation code under test."""

import json

import imageio.v3 as iio
import dask.array as da
import numpy as np
import pytest

from clwave.cli import main
from clwave.errors import InputError
from clwave.io.loaders import load
from clwave.model.volume import Volume
from test_loaders import assert_one_line_error, place_in_ras, write_dicom_slice


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


#: (ImageOrientationPatient, where its stack's x, y, z point): an axial series, rows to the left and columns to the
#: back (LPS), slices up; a coronal one, columns down, slices along row x column = posterior
SERIES = {"axial": ((1, 0, 0, 0, 1, 0), "LPS"), "coronal": ((1, 0, 0, 0, 0, -1), "LIP")}


@pytest.mark.parametrize("series", SERIES)
def test_a_stack_given_the_dicom_series_orientation_loads_as_the_series(tmp_path, rng, series):
    """trial25 M2: the photo stack and the CT of one subject came out turned 180 degrees about z. The same pixels
    as a DICOM series and as a 16-bit PNG folder (slices in the series' order), the folder given the series'
    orientation, its spacing (z first, as stored) and its origin, load to the same volume."""
    cosines, codes = SERIES[series]
    stored = rng.integers(0, 4000, (4, 6, 5)).astype(np.uint16)
    (tmp_path / "ct").mkdir()
    (tmp_path / "photo").mkdir()
    normal = np.cross(cosines[:3], cosines[3:])
    for k, pixels in enumerate(stored):
        position = np.array([-20.0, 30.0, 12.0]) + 2.5 * k * normal
        write_dicom_slice(tmp_path / "ct" / f"s{k}.dcm", pixels, position, "1.2.3", orientation=cosines,
                          pixel_spacing=(0.7, 0.9), rescale=(1, 0))
        iio.imwrite(tmp_path / "photo" / f"slice_{k + 1}.png", pixels)
    ct = load(tmp_path / "ct", progress_bar=False)
    photo = load(tmp_path / "photo", spacing=(2.5, 0.7, 0.9), orientation=codes, origin=ct.origin)
    np.testing.assert_array_equal(photo.data, ct.data)
    assert photo.spacing == pytest.approx(ct.spacing) and photo.origin == ct.origin
    assert (photo.unit, ct.unit) == (None, "mm")  # PNG gives no unit; the CT's millimetres are the DICOM's
    as_stored = load(tmp_path / "photo")
    assert not np.array_equal(as_stored.data, ct.data)  # the trial's mismatch without it
    assert load(tmp_path / "photo", orientation=codes.lower()).shape == ct.shape  # codes in either case


@pytest.mark.parametrize("codes", ["RAS", "LPS", "PIR", "SLA", "IRP"])
def test_orientation_places_each_voxel_where_its_codes_point(tmp_path, rng, codes):
    """Each voxel of a (z, y, x) .npy lands where the codes say its x, y, z index axes point (nibabel's
    aff2axcodes of the (x, y, z) array), its spacing with it; the origin, the centre's place, stays 0.  Volume takes
    orientation= as load does (trial30: a raw TypeError), its origin= after the turn, a Dask array kept lazy."""
    data = rng.integers(0, 1000, (3, 4, 5)).astype(np.int16)
    np.save(tmp_path / "v.npy", data)
    spacing_zyx = (3.0, 2.0, 0.5)
    unit = {"R": (1, 0, 0), "L": (-1, 0, 0), "A": (0, 1, 0), "P": (0, -1, 0), "S": (0, 0, 1), "I": (0, 0, -1)}
    affine = np.eye(4)  # (x, y, z) index -> RAS, by hand from the letters
    affine[:3, :3] = np.array([unit[c] for c in codes]).T * spacing_zyx[::-1]
    vol = load(tmp_path / "v.npy", spacing=spacing_zyx, orientation=codes)
    np.testing.assert_array_equal(vol.data, place_in_ras(data.transpose(2, 1, 0), affine))
    ras_axis = [int(np.flatnonzero(unit[c])[0]) for c in codes]  # the RAS axis of x, y, z
    expected = {ras_axis[a]: spacing_zyx[2 - a] for a in range(3)}  # RAS axis -> spacing
    assert vol.spacing == (expected[2], expected[1], expected[0]) and vol.origin == (0.0, 0.0, 0.0)
    api = Volume(data, spacing=spacing_zyx, orientation=codes, origin=(1, 2, 3))
    np.testing.assert_array_equal(api.data, place_in_ras(data.transpose(2, 1, 0), affine))
    assert api.spacing == vol.spacing and api.origin == (1.0, 2.0, 3.0) and type(api.spacing[0]) is float
    assert api.data.flags.c_contiguous and api.data.dtype == np.float32  # what the renderers take
    lazy = Volume(da.from_array(data, chunks=2), spacing=spacing_zyx, orientation=codes)
    assert lazy.chunked and lazy.spacing == vol.spacing
    np.testing.assert_array_equal(lazy.data.compute(), vol.data)


def test_a_files_origin_turns_with_its_axes_and_origin_places_the_centre(tmp_path):
    """An OME-Zarr's origin (its centre, from its translation) is a point in its own axes: turned with them; origin=
    is where the centre goes, in world (RAS) coordinates, after the turn."""
    from test_chunked_inputs import _make_zarr

    _make_zarr()([str(tmp_path / "o.zarr"), "--shape", "4,6,8", "--ome", "--spacing", "2,1,0.5", "--origin",
                  "10,20,30", "--dtype", "uint16"])
    stored = load(tmp_path / "o.zarr")
    centre = np.array(stored.origin)  # (x, y, z) of the centre as stored; "LIP": x -> -x, y -> -z, z -> -y
    turned = load(tmp_path / "o.zarr", orientation="LIP")
    assert turned.origin == pytest.approx((-centre[0], -centre[2], -centre[1]))
    np.testing.assert_array_equal(turned.data.compute(), stored.data.compute().transpose(1, 0, 2)[::-1, ::-1, ::-1])
    assert load(tmp_path / "o.zarr", orientation="LIP", origin=(1, 2, 3)).origin == (1.0, 2.0, 3.0)
    assert load(tmp_path / "o.zarr", origin=(1, 2, 3)).origin == (1.0, 2.0, 3.0)


def test_orientation_is_refused_for_oriented_files_and_bad_codes(tmp_path, rng, capsys):
    """A DICOM, NIfTI, MGH or NRRD input carries its own orientation: orientation= is refused for it in one line, as
    codes that are not one of L/R, A/P and I/S each are; the command line says the same with its flag."""
    import nibabel as nib
    import nrrd

    (tmp_path / "ct").mkdir()
    for k in range(3):
        write_dicom_slice(tmp_path / "ct" / f"s{k}.dcm", np.zeros((4, 4)), (0, 0, k), "1.2.3")
    nib.save(nib.Nifti1Image(np.zeros((3, 4, 5), np.float32), np.eye(4)), tmp_path / "v.nii")
    nrrd.write(str(tmp_path / "v.nrrd"), np.zeros((3, 4, 5), np.float32))
    nib.save(nib.MGHImage(np.zeros((3, 4, 5), np.float32), np.eye(4)), tmp_path / "v.mgz")
    for name in ("ct", "v.nii", "v.nrrd", "v.mgz"):
        with pytest.raises(InputError, match="orientation= is for inputs that carry none") as excinfo:
            load(tmp_path / name, orientation="LPS")
        assert_one_line_error(excinfo)
    np.save(tmp_path / "v.npy", np.zeros((3, 4, 5), np.float32))
    for codes in ("LPX", "LLS", "LP", "LPSA", "", 3):
        with pytest.raises(InputError, match="must be three axis codes, one of L/R, one of A/P and one of I/S") as e:
            load(tmp_path / "v.npy", orientation=codes)
        assert_one_line_error(e)
        with pytest.raises(InputError, match="must be three axis codes, one of L/R, one of A/P and one of I/S") as e:
            Volume(np.zeros((3, 4, 5)), orientation=codes)
        assert_one_line_error(e)
    code, out, err = run(capsys, "info", str(tmp_path / "v.nii"), "--orientation", "LPS")
    assert code == 2 and err.strip().endswith("--orientation is for inputs that carry none (.npy, .raw, TIFF, "
                                              "folders of slices, Zarr, HDF5, MRC); a nifti input is put in RAS+ by "
                                              "its own header: leave it out"), err
    code, out, err = run(capsys, "info", str(tmp_path / "v.npy"), "--orientation", "XYZ")
    assert code == 2 and "--orientation XYZ must be three letters" in err and len(err.splitlines()) == 1, err


def test_spacing_keeps_the_files_unit_and_unit_names_one(tmp_path, rng, capsys):
    """trial25 M4: load(dicom, spacing=...) gave unit None (the file's millimetres dropped) and a PNG folder could
    never be in mm on the command line. spacing= re-states the numbers in the file's unit; unit= names one."""
    (tmp_path / "ct").mkdir()
    (tmp_path / "photo").mkdir()
    for k in range(3):
        write_dicom_slice(tmp_path / "ct" / f"s{k}.dcm", np.zeros((4, 4)), (0, 0, k), "1.2.3")
        iio.imwrite(tmp_path / "photo" / f"s{k}.png", np.zeros((4, 4), np.uint8))
    assert load(tmp_path / "ct", spacing=(1, 0.33, 0.33)).unit == "mm"
    assert load(tmp_path / "ct", unit="cm").unit == "cm"
    assert load(tmp_path / "photo", spacing=(1, 0.33, 0.33)).unit is None
    assert load(tmp_path / "photo", unit="mm").unit == "mm"
    with pytest.raises(InputError, match="unit='furlong' must be the world unit") as excinfo:
        load(tmp_path / "photo", unit="furlong")
    assert_one_line_error(excinfo)
    code, out, err = run(capsys, "info", str(tmp_path / "photo"), "--spacing", "1,0.33,0.33", "--unit", "mm",
                         "--json")
    assert code == 0 and json.loads(out)["unit"] == "mm", err
    code, out, err = run(capsys, "info", str(tmp_path / "ct"), "--spacing", "1,0.5,0.5")
    assert code == 0 and "box        2, 2, 3 (x, y, z) mm" in out, out


def test_info_prints_the_spacing_option_that_gives_its_spacing(tmp_path, capsys):
    """trial25 P3: info printed spacing as (x, y, z) and --spacing takes DZ,DY,DX: its line now names the --spacing
    argument, z first, and that argument read back gives the same spacing; with --orientation the shape, spacing and
    origin are turned as load turns them, the argument still along the axes as stored."""
    np.save(tmp_path / "v.npy", np.zeros((3, 4, 5), np.int16))
    code, out, err = run(capsys, "info", str(tmp_path / "v.npy"), "--spacing", "1,0.33,0.25")
    lines = dict(line.split(None, 1) for line in out.splitlines())
    assert code == 0 and lines["spacing"] == "0.25, 0.33, 1 (x, y, z; --spacing 1,0.33,0.25 given), centre 0, 0, " \
        "0, corner voxel (least x, y, z) -0.5, -0.495, -1"
    code, out, err = run(capsys, "info", str(tmp_path / "v.npy"), "--spacing", "1,0.33,0.25", "--orientation", "PIR",
                         "--json")
    facts = json.loads(out)
    vol = load(tmp_path / "v.npy", spacing=(1, 0.33, 0.25), orientation="PIR")
    assert code == 0 and (tuple(facts["shape"]), tuple(facts["spacing"]), tuple(facts["origin"])) == \
        (vol.shape, vol.spacing, vol.origin)
    assert facts["spacing_option"] == "--spacing 1,0.33,0.25"
    code, out, err = run(capsys, "info", str(tmp_path / "v.npy"), "--orientation", "PIR")
    lines = dict(line.split(None, 1) for line in out.splitlines())
    assert lines["spacing"] == "1, 1, 1 (x, y, z; --spacing 1,1,1, before --orientation PIR turns it: none in the " \
                               "file, give yours), centre 0, 0, 0, corner voxel (least x, y, z) -1, -2, -1.5 " \
                               "(RAS+)", out  # the turned shape: 3 x 5 x 4 (x, y, z)
