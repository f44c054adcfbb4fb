"""Hostile files by mutation, again (fuzz29: each format's valid files with one header field, card, line or stream
changed; docs/known-gaps.md §15): each class refused in one line naming the problem, with no warning of NumPy's on
the way (pyproject's filterwarnings make one an error here)."""

import struct

import numpy as np
import pytest

import clwave
from clwave.errors import InputError
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
