"""Hostile files by mutation, again (fuzz29: each format's valid files with one header field, card, line or stream
changed, and the transfer-function and pose-table files the command line reads; docs/known-gaps.md §15): each class
refused in one line naming the problem, with no warning of NumPy's on the way (pyproject's filterwarnings make one an
error here)."""

import struct

import numpy as np
import pytest

import clwave
from clwave.errors import InputError
from clwave.model.tf_file import named_transfer_function
from test_cli import run
from test_fits import SKY
from test_fits import write as write_fits
from test_mgh import assert_refused_in_one_line


def _nifti(path, affine, kind="Nifti1Image", data=None, slope=None):
    import nibabel as nib

    image = getattr(nib, kind)(np.ones((4, 5, 6), np.float32) if data is None else data, affine)
    if slope is not None:
        image.header.set_slope_inter(slope, 0.0)
    nib.save(image, path)
    return path


@pytest.mark.parametrize("kind, entry, value", [
    ("Nifti1Image", (2, 1), 3e38),  # srow_z[1]: finite, but its squares are not (nibabel's aff2axcodes overflowed)
    ("Nifti2Image", (2, 0), 1e20),  # srow_z[0]: the straight grid's QR divided by 0 (NaN), "cannot convert NaN"
    ("Nifti1Image", (0, 0), 1e-5),  # voxels 1e5 times longer one way than another
])
def test_a_nifti_affine_of_voxels_uneven_past_any_scanner_is_refused_by_its_header(tmp_path, capsys, kind, entry,
                                                                                   value):
    """An sform entry of 3e38 or 1e20 beside 1 and 2: NumPy's "invalid value encountered in divide" twice (four
    lines), then "cannot read: ValueError: cannot convert float NaN to integer"; a voxel 1e5 times thinner than
    the others was read, its footprint textures or straight grid past the memory."""
    affine = np.diag([1.0, 1.2, 2.0, 1.0])
    affine[entry] = value
    path = _nifti(tmp_path / "v.nii", affine, kind)
    assert_refused_in_one_line(capsys, path, r"affine .* is not finite or not invertible, or its voxels are more "
                                             r"than 10000 times longer")


def test_an_mgh_whose_direction_cosines_are_not_unit_is_refused(tmp_path, capsys):
    """Mdc's rows are the axes' directions, delta their voxel's size: a row of length 2 was read as voxels twice as
    long (a mutant's row of length 699, 89.9 degrees oblique, made 839 mm voxels beside 1 mm, and its render asked for
    17 GiB of footprint textures)."""
    import nibabel as nib

    nib.save(nib.MGHImage(np.ones((4, 5, 6), np.float32), np.diag([1.0, 1.2, 2.0, 1.0])), tmp_path / "v.mgh")
    content = bytearray((tmp_path / "v.mgh").read_bytes())
    struct.pack_into(">f", content, 58, 2.0)  # Mdc[1][1]: the second axis's y component, 1 before
    (tmp_path / "w.mgh").write_bytes(bytes(content))
    assert_refused_in_one_line(capsys, tmp_path / "w.mgh", r"its Mdc .* rows of length 1, 2, 1, not 1")


def test_a_sheared_nifti_scaled_past_float32_is_refused_without_a_warning(tmp_path, capsys):
    """scl_slope 3e38 on a sheared float32 NIfTI: NumPy's "overflow encountered in cast" (two lines) while the straight
    grid was resampled, then the non-finite voxels' line (unsheared, the range's own line)."""
    affine = np.diag([1.0, 1.2, 2.0, 1.0])
    affine[1, 2] = 0.4
    path = _nifti(tmp_path / "v.nii", affine, data=np.arange(120, dtype=np.float32).reshape(4, 5, 6), slope=3e38)
    with pytest.raises(InputError, match=r"holds values up to 3\.57e\+40, beyond float32's range"):
        clwave.load(path)
    code, out, err = run(capsys, "render", str(path), "-o", str(tmp_path / "a.png"), "--levels", "1")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "values up to" in err, err
    assert not (tmp_path / "a.png").exists()


@pytest.mark.parametrize("card, words", [
    ("CDELT2  =  `             0.001", r"card CDELT2 cannot be parsed"),  # astropy.wcs left it out: 1 degree
    ("NAXIS3  =               -0.001", r"NAXIS3 twice, 10 and -0\.001"),  # "TypeError: 'float' object cannot be"
])
def test_a_fits_card_clwave_reads_that_astropy_cannot_or_given_twice_is_refused(tmp_path, capsys, card, words):
    """An unparsable CDELT2 was left out by astropy.wcs without a word: the sky's pixels 1000 times taller than wide
    (its default step, 1 degree, against CDELT1's 0.001), and 1.2 GiB of footprint textures asked for; a second NAXIS3
    of another value was read by astropy's section (a TypeError as "corrupt") after ``clwave info`` described the
    first."""
    path = write_fits(tmp_path / "c.fits", np.ones((10, 12, 14), np.float32), -32, SKY)
    content, image = path.read_bytes(), card.ljust(80).encode()
    if card.startswith("NAXIS3"):  # a second one, before END (in the header's padding)
        end = content.index(b"END     ")
        path.write_bytes(content[:end] + image + content[end:end + 80] + content[end + 160:])
    else:
        start = content.index(card[:8].encode())
        path.write_bytes(content[:start] + image + content[start + 80:])
    assert_refused_in_one_line(capsys, path, words)


def test_a_projection_matrix_past_float_range_is_refused_without_a_warning(tmp_path, capsys):
    """A pose table's p22 of 1e308: NumPy's "overflow encountered in det" and "in dot" (four lines) before the
    singular matrix's line; a matrix is homogeneous, weighed at its own scale."""
    rows = "p00,p01,p02,p03,p10,p11,p12,p13,p20,p21,p22,p23\n150,0,16,0,0,150,16,0,0,0,1e308,100\n"
    (tmp_path / "p.csv").write_text(rows)
    with pytest.raises(InputError, match="singular"):
        clwave.ConeBeam.from_matrix([[150, 0, 16, 0], [0, 150, 16, 0], [0, 0, 1e308, 100]], 32)
    np.save(tmp_path / "v.npy", np.ones((6, 7, 8), np.float32))
    code, out, err = run(capsys, "drr", str(tmp_path / "v.npy"), "--poses", str(tmp_path / "p.csv"), "--size", "16",
                         "-o", str(tmp_path / "d.png"), "--levels", "1")
    assert code == 2 and err.strip().splitlines() == [
        f"clwave: error: pose table {tmp_path / 'p.csv'}, pose 1: the projection matrix is singular: its left 3 x 3 "
        "block must be invertible"], err


def test_a_refusal_quoting_a_files_control_characters_stays_one_line(tmp_path, capsys):
    """A pose table's header of a flipped bit, "elevation\\froll": its refusal quoted the form feed, which breaks
    the line it is printed on (as a vertical tab or a file separator, \\x1c, would)."""
    (tmp_path / "p.csv").write_text("azimuth,elevation\froll,\x1cdso\x1cx\n0,0,100\n")
    np.save(tmp_path / "v.npy", np.ones((6, 7, 8), np.float32))
    code, out, err = run(capsys, "drr", str(tmp_path / "v.npy"), "--poses", str(tmp_path / "p.csv"), "--size", "16",
                         "-o", str(tmp_path / "d.png"), "--levels", "1")
    assert code == 2 and len(err.splitlines()) == 1 and "unknown column(s) dso x, elevation roll;" in err, err


def test_a_projection_matrix_at_any_scale_is_the_same_geometry():
    """Scaled by 1e-300 or 1e300 a matrix is the same projection (the check against overflow divides by its largest
    entry): its source, pixel and axes as at scale 1."""
    P = np.array([[150.0, 0, 16, 5], [0, 150, 16, 0], [0, 0, 1, 100]])
    one = clwave.ConeBeam.from_matrix(P, 32)
    for scale in (1e-300, 1e300):
        other = clwave.ConeBeam.from_matrix(P * scale, 32)
        np.testing.assert_allclose(other.source, one.source, rtol=1e-12)
        np.testing.assert_allclose(other.slope, one.slope, rtol=1e-12)
        np.testing.assert_allclose(other.n, one.n, atol=1e-15)


@pytest.mark.parametrize("points, words", [
    ([(0, 0, 0, 0, 0), (1, 1, 0, 0, 1e308)], r"point 1 .* beyond float32's range"),  # "overflow encountered in cast"
    ([(-1e308, 0, 0, 0, 0), (1e308, 1, 0, 0, 1)], r"point 0 .* beyond float32's range"),  # "in subtract"
])
def test_transfer_function_numbers_past_float32_are_refused(points, words):
    """An opacity or value of 1e308 (a mutated .json): NumPy's overflow warnings (two to eight lines) while the volume
    was classified, then the non-finite voxels' line."""
    with pytest.raises(InputError, match=words):
        clwave.TransferFunction(points)
    with pytest.raises(InputError, match=r"point 1 .* beyond float32's range"):
        clwave.TransferFunction.labels({1: (1, 0, 0, 1e308), 2: (0, 1, 0, 0.5)})


def test_a_transfer_function_row_is_quoted_short(tmp_path, capsys):
    """A .csv row of 500 NUL bytes was quoted whole in its refusal (a line of 2,600 characters)."""
    (tmp_path / "tf.csv").write_bytes(b"value,r,g,b,opacity\n0,0,0,0,0\n1,1,1,1,1\n" + bytes(500))
    with pytest.raises(InputError, match=r"row 4 .* is not 5 numbers") as excinfo:
        named_transfer_function(str(tmp_path / "tf.csv"))
    assert len(str(excinfo.value)) < 300, str(excinfo.value)
