"""Loose ends in the readers (loose30; docs/known-gaps.md §15, fuzz29 and bomb29's "Left:"): an HDF5 deflate chunk
decoded once, to its size; every HDF5 filter bounded or refused by its name."""

import numpy as np
import pytest

import clwave
from clwave.errors import FileFormatError
from clwave.io.loaders import describe


def _h5(path, data, chunks, **filters):
    import h5py

    with h5py.File(path, "w") as h5:
        h5.create_dataset("v", data=data, chunks=chunks, **filters)
    return path


@pytest.mark.parametrize("filters", [{"compression": "gzip"}, {"compression": "gzip", "shuffle": True}])
def test_an_hdf5_deflate_volume_is_decoded_by_clwave_once_and_reads_as_hdf5_reads_it(tmp_path, monkeypatch, filters):
    """Chunks that overhang the volume, one never written (the fill value), one stored unfiltered (its filter mask
    set), big-endian floats: the same values as HDF5's own read (the oracle), whole and chunk by chunk, and h5py's
    decoding read never called (each chunk inflated once, by clwave, to its bytes and no further)."""
    import h5py

    rng = np.random.default_rng(30)
    data = rng.normal(size=(11, 13, 7)).astype(">f4")
    path = _h5(tmp_path / "v.h5", data, (4, 5, 3), fillvalue=-7.0, **filters)
    with h5py.File(path, "r+") as h5:
        h5["v"].id.write_direct_chunk((4, 5, 3), np.arange(60, dtype=">f4").tobytes(), filter_mask=0b11)
        h5.create_dataset("w", shape=data.shape, dtype=">f4", chunks=(4, 5, 3), fillvalue=-7.0, **filters)
        h5["w"][:8] = data[:8]  # its last chunks never written
        expected, sparse = h5["v"][...], h5["w"][...]
    assert expected[4:8, 5:10, 3:6].ravel().tolist() == list(range(60)) and (sparse[8:] == -7).all()
    monkeypatch.setattr(h5py.Dataset, "__getitem__", lambda *_: pytest.fail("h5py decoded a deflate chunk"))
    for name, want in (("v", expected), ("w", sparse)):
        for chunks in (False, 4):
            got = np.asarray(clwave.load(f"{path}:/{name}", orientation=None, chunks=chunks).data)
            np.testing.assert_array_equal(got, want, err_msg=f"{name} {chunks}")


def test_an_hdf5_deflate_chunk_shorter_than_its_chunk_is_refused_in_one_line(tmp_path):
    import zlib

    import h5py

    path = _h5(tmp_path / "short.h5", np.zeros((8, 8, 8), np.uint8), (8, 8, 4), compression="gzip")
    with h5py.File(path, "r+") as h5:
        h5["v"].id.write_direct_chunk((0, 0, 0), zlib.compress(bytes(255)))
    with pytest.raises(FileFormatError, match=r"its chunk at \(0, 0, 0\): holds 255 bytes, not the 256 of its chunk"):
        np.asarray(clwave.load(path).data)


def test_an_hdf5_filter_clwave_cannot_weigh_is_refused_by_its_name_before_a_chunk_is_read(tmp_path):
    """Scale-offset allocates what its parameters say, hdf5plugin's LZ4 what its stream holds: refused at the
    header (``clwave info`` too), with the fix."""
    import hdf5plugin

    data = np.arange(4096, dtype=np.int16).reshape(16, 16, 16)
    for name, filters in (("scaleoffset", {"scaleoffset": 0}), ("lz4", dict(hdf5plugin.LZ4()))):
        path = _h5(tmp_path / f"{name}.h5", data, (16, 16, 8), **filters)
        for call in (clwave.load, describe):
            with pytest.raises(FileFormatError, match=rf"^member {path}:/v is filtered by '[^']*{name}[^']*' "
                                                      r"\(id \d+\), whose chunks clwave cannot weigh before they are "
                                                      "decoded: write it again with gzip, lzf or Zstandard, e.g. "
                                                      "h5repack -f GZIP=4 IN OUT$"):
                call(path)


def test_an_hdf5_lzf_volume_is_read_and_its_forged_buffer_or_chunk_refused(tmp_path):
    """h5py's lzf decoder allocates the buffer its parameters state, then grows it by the stored size until the
    stream fits: a buffer past the chunk's bytes, or a chunk stored in more than them, is refused."""
    import h5py

    data = np.arange(4096, dtype=np.float32).reshape(16, 16, 16)
    path = _h5(tmp_path / "lzf.h5", data, (16, 16, 8), compression="lzf")
    np.testing.assert_array_equal(np.asarray(clwave.load(path, orientation=None).data), data)
    with h5py.File(path, "r+") as h5:
        h5["v"].id.write_direct_chunk((0, 0, 0), bytes(8193))
    with pytest.raises(FileFormatError, match=r"its chunk at \(0, 0, 0\): an lzf chunk is stored in 8,193 bytes, more "
                                              "than the 8,192"):
        np.asarray(clwave.load(path).data)
    raw = bytearray((tmp_path / "lzf.h5").read_bytes())
    at = raw.index((8192).to_bytes(4, "little"), raw.index(b"lzf"))
    raw[at:at + 4] = (1 << 31).to_bytes(4, "little")
    (tmp_path / "forged.h5").write_bytes(bytes(raw))
    with pytest.raises(FileFormatError, match="its lzf filter states a buffer of 2,147,483,648 bytes, more than its "
                                              "chunk's 8,192"):
        np.asarray(clwave.load(tmp_path / "forged.h5").data)


def _nifti(path, kind, data, slope, inter=0.0):
    import nibabel as nib

    image = getattr(nib, kind)(data, np.eye(4))
    image.header.set_slope_inter(slope, inter)
    nib.save(image, path)
    return path


def test_a_nifti2_scl_slope_that_underflows_float32_is_refused_and_nifti1s_subnormal_one_read(tmp_path, capsys):
    """NIfTI-2's float64 ``scl_slope`` of 1e-310 made every voxel 0 in float32, rendered blank unwarned; NIfTI-1's
    float32 1e-45 (the least subnormal) keeps the stored values apart, read as they scale (the oracle: NumPy's
    float32 of stored x 1e-45)."""
    from test_mgh import assert_refused_in_one_line

    stored = np.arange(60, dtype=np.int16).reshape(3, 4, 5)
    path = _nifti(tmp_path / "blank.nii", "Nifti2Image", stored, 1e-310)
    assert_refused_in_one_line(capsys, path, r"blank\.nii has scl_slope = 1e-310 and scl_inter = 0\.0, which map every "
                                             r"int16 sample to 0 in float32 \(its volume would be one value\); the "
                                             "header is corrupt: correct its scl_slope$")
    kept = clwave.load(_nifti(tmp_path / "tiny.nii", "Nifti1Image", stored, 1e-45), orientation=None).data
    got = np.asarray(kept, np.float32)
    assert np.unique(got).size == 60 and got.max() == np.float32(59 * 1.401298464324817e-45)


def test_a_dicom_rescale_and_a_fits_bscale_that_underflow_are_refused_by_their_header(tmp_path, capsys, rng):
    """The same class in the other formats' scaling (one home, ``scaling.check_scaling``): a RescaleSlope of 1e-320
    (every uint16 pixel the intercept 0), a BSCALE of 1e-300 on float32 samples (every pixel 0)."""
    from test_fits import write as write_fits
    from test_loaders import write_series
    from test_mend28 import _refused_alike

    write_series(tmp_path, rng, [(0.0, 0.0, float(z)) for z in range(3)], "1.2.3", ["a", "b", "c"],
                 rescale=(1e-320, 0))
    _refused_alike(capsys, tmp_path, r"has RescaleSlope = 1e-320 and RescaleIntercept = 0\.0, which map every uint16 "
                                     r"sample to 0 in float32")
    path = write_fits(tmp_path / "c.fits", np.arange(24, dtype=np.float32).reshape(2, 3, 4), -32, {"BSCALE": 1e-300})
    _refused_alike(capsys, path, r"its HDU 0 has BSCALE = 1e-300 and BZERO = 0, which map every float32 sample to 0 in "
                                 r"float32")


@pytest.mark.parametrize("stored, slope, inter, refused", [
    ("int16", 2.0 ** -149 / 2 ** 17, 0.0, True),  # -32768 and 32767 times it under half the least subnormal: both 0
    ("int16", 2.0 ** -149, 0.0, False),  # each end a multiple of the least subnormal: apart
    ("int8", 1.0, 2.0 ** 40, True),  # -128 .. 127 about 2^40, where float32's step is 2^17: one value
    ("int8", 1.0, 2.0 ** 20, False),  # where its step is 2^-3: apart
    ("uint8", 0.0, 5.0, True), ("float32", 1.0, 0.0, False)])
def test_check_scaling_refuses_a_scaling_on_the_far_side_of_its_edge_only(stored, slope, inter, refused):
    """Both sides of the edge where a scaling maps the stored type's whole range to one float32 (the oracle: float32's
    least subnormal 2^-149 and its step 2^(e - 23) at 2^e, by hand)."""
    from clwave.io.loaders.scaling import check_scaling

    if refused:
        with pytest.raises(FileFormatError, match=rf"^f has S = .* which map every {stored} sample to .* in float32"):
            check_scaling("f", ("S", "I"), slope, inter, stored)
    else:
        assert check_scaling("f", ("S", "I"), slope, inter, stored) is None


def test_info_refuses_a_fits_cube_astropy_cannot_open_and_a_slice_folder_of_another_size(tmp_path, capsys):
    """``EXTEND = NaN`` (fuzz29: 17 mutants) passed clwave's header checks, ``clwave info`` described it and each read
    of a chunk failed ("Empty or corrupt FITS file"); a folder of TIFF or PNG slices with one of another size was
    described by its first slice and refused by the read: both refused by ``info``, ``load`` and ``render`` alike."""
    import imageio.v3 as iio
    import tifffile

    from test_fits import SKY
    from test_fits import write as write_fits
    from test_mend28 import _refused_alike

    path = write_fits(tmp_path / "c.fits", np.ones((10, 12, 14), np.float32), -32, SKY)
    content = path.read_bytes()
    end = content.index(b"END     ")
    path.write_bytes(content[:end] + b"EXTEND  =                  NaN".ljust(80) + content[end:end + 80]
                     + content[end + 160:])
    _refused_alike(capsys, path, r"c\.fits: astropy cannot open its HDU 0 \(Empty or corrupt FITS file\); a card "
                                 r"astropy requires is not what FITS allows \(as EXTEND = NaN\): correct the header$")
    for suffix, write in ((".tif", tifffile.imwrite), (".png", iio.imwrite)):
        folder = tmp_path / suffix[1:]
        folder.mkdir()
        for k in range(3):
            write(folder / f"s{k}{suffix}", np.zeros((6, 7) if k != 2 else (6, 8), np.uint8))
        _refused_alike(capsys, folder, rf"slice {folder / f's2{suffix}'} has shape \(6, 8\) of uint8 but s0{suffix} "
                                       r"has \(6, 7\) of uint8; all slices")


def test_a_nrrd_spacing_of_infinity_is_refused_not_taken_as_unknown(tmp_path, capsys):
    """``spacings: inf`` was taken as 1 with the warning of an unknown (nan) spacing; NaN still is (NRRD's unknown)."""
    from test_mgh import assert_refused_in_one_line

    head = b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 3 4\nspacings: %s 1 2\nencoding: raw\n\n"
    (tmp_path / "inf.nrrd").write_bytes(head % b"inf" + bytes(24))
    assert_refused_in_one_line(capsys, tmp_path / "inf.nrrd", r"inf\.nrrd: its spacings \(dz, dy, dx\) 2\.0, 1\.0, inf "
                                                              r"include an infinite one; correct the header's spacings")
    (tmp_path / "nan.nrrd").write_bytes(head % b"nan" + bytes(24))
    assert clwave.load(tmp_path / "nan.nrrd", spacing=(1, 1, 1)).data.shape == (4, 3, 2)
