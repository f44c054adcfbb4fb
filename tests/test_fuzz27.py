"""Hostile headers found by mutation (fuzz27: each format's valid files with one header field, length or stream
changed; docs/known-gaps.md §15): each class refused in one line naming the field, before the data is read and with
no warning of NumPy's on the way (pyproject's filterwarnings make one an error here)."""

import gzip
import struct

import numpy as np
import pytest

import clwave
from clwave.errors import FileFormatError
from test_cli import run
from test_hardening import crafted
from test_fits import write as write_fits
from test_mgh import assert_refused_in_one_line


@pytest.mark.parametrize("cards, words", [
    ({"BSCALE": 0.0}, r"BSCALE = 0\.0 and BZERO = 0, which map every int16 sample to 0 in float32"),
    ({"BSCALE": 1e308}, r"BSCALE = 1e\+308, beyond float32's range"),
    ({"BZERO": -1e308}, r"BZERO = -1e\+308, beyond float32's range"),
])
def test_a_fits_scaling_no_float32_cube_holds_is_refused_by_name(tmp_path, capsys, cards, words):
    """BSCALE 0 rendered a blank image (every pixel BZERO); BSCALE or BZERO beyond float32's range gave NumPy's
    overflow warnings (four lines) before the non-finite voxels' line."""
    path = write_fits(tmp_path / "c.fits", np.arange(24, dtype=np.int16).reshape(2, 3, 4), 16, cards)
    assert_refused_in_one_line(capsys, path, words)


def test_fits_values_scaled_past_float32_are_named_without_a_warning(tmp_path, capsys):
    """A BSCALE within float32's range whose products are not (1e38 x 1000): the non-finite voxels' one line, not
    NumPy's overflow warnings before it."""
    path = write_fits(tmp_path / "c.fits", np.full((2, 3, 4), 1000, np.int16), 16, {"BSCALE": 1e38})
    with pytest.raises(clwave.errors.InputError, match="non-finite"):
        clwave.load(path)
    code, out, err = run(capsys, "render", str(path), "-o", str(tmp_path / "a.png"), "--levels", "1")
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "a.png").exists()


def test_a_tile_compressed_fits_with_a_tile_of_no_pixels_is_refused_by_name(tmp_path, capsys):
    """ZTILE1 = 0: NumPy's division warning, then astropy's "OverflowError: cannot convert float infinity to
    integer"."""
    from astropy.io import fits

    fits.HDUList([fits.PrimaryHDU(), fits.CompImageHDU(np.ones((4, 5, 6), np.float32))]).writeto(tmp_path / "c.fz")
    content = (tmp_path / "c.fz").read_bytes()
    tile = b"ZTILE1  =                    6"
    assert tile in content
    (tmp_path / "d.fz").write_bytes(content.replace(tile, b"ZTILE1  =                    0"))
    assert_refused_in_one_line(capsys, tmp_path / "d.fz", r"ZTILE1 = 0; a tile needs at least one pixel")


@pytest.mark.parametrize("field, value", [("delta", float("inf")), ("delta", 3e38), ("Mdc", 3e38)])
def test_an_mgh_geometry_beyond_float_is_refused_without_a_warning(tmp_path, capsys, field, value):
    """An MGH's delta or Mdc of inf, or whose vox2ras overflows float32 (3e38 x 2 voxels), was refused in its line
    after nibabel's overflow warnings (two to four lines)."""
    import nibabel as nib

    nib.save(nib.MGHImage(np.ones((4, 5, 6), np.float32), np.eye(4)), tmp_path / "v.mgh")
    content = bytearray((tmp_path / "v.mgh").read_bytes())
    struct.pack_into(">f", content, {"delta": 30, "Mdc": 42}[field], value)
    (tmp_path / "w.mgh").write_bytes(bytes(content))
    with pytest.raises(FileFormatError, match=r"its vox2ras .* is not finite or not invertible"):
        clwave.load(tmp_path / "w.mgh")
    code, out, err = run(capsys, "info", str(tmp_path / "w.mgh"))
    assert code == 2 and len(err.strip().splitlines()) == 1 and not out, err


def test_a_nrrd_gzip_stream_longer_than_its_header_declares_is_refused_before_it_is_decompressed(tmp_path, capsys,
                                                                                                 monkeypatch):
    """A 960-byte volume whose gzip stream goes on for 64 MiB of zeros (64 KiB compressed; 1 GiB in 1 MiB took 70 s
    and 2.2 GB): pynrrd decompressed all of it before it compared the sizes."""
    import nrrd

    head = (b"NRRD0004\ntype: short\ndimension: 3\nsizes: 8 10 6\nendian: little\nencoding: gzip\n"
            b"spacings: 1 1 1\n\n")
    body = np.arange(480, dtype="<i2").tobytes()
    (tmp_path / "v.nrrd").write_bytes(head + gzip.compress(body + bytes(64 << 20)))
    monkeypatch.setattr(nrrd, "read_data", lambda *a, **k: pytest.fail("the stream was decompressed"))
    assert_refused_in_one_line(capsys, tmp_path / "v.nrrd", r"its gzip stream holds 67,109,824 bytes or more, "
                                                            r"more than the 960 bytes its header declares")
    (tmp_path / "w.nrrd").write_bytes(head + gzip.compress(body))  # the stream it declares: read
    monkeypatch.undo()
    np.testing.assert_array_equal(clwave.load(tmp_path / "w.nrrd", orientation=None).data.shape, (6, 10, 8))


@pytest.mark.parametrize("member", ["g0/positions", "g0/runs", "g0/values"])
def test_a_clw_member_that_is_a_group_is_refused_by_name(model_file, tmp_path, capsys, member):
    """A member replaced by an HDF5 group: "internal error (AttributeError: 'Group' object has no attribute 'ndim')"
    (clwave info, positions), 'shape' (WaveletVolume.open, runs)."""
    path = crafted(model_file, tmp_path, change=lambda h5: (h5.__delitem__(member), h5.create_group(member)))
    with pytest.raises(FileFormatError, match="a member is missing or not a dataset"):
        clwave.WaveletVolume.open(path)
    code, out, err = run(capsys, "render", str(path), "-o", str(tmp_path / "a.png"))
    assert code == 2 and len(err.strip().splitlines()) == 1 and "missing or not a dataset" in err, err


@pytest.mark.parametrize("scale", [3.0, 2.0 ** 40])
def test_a_clw_content_box_off_its_voxels_faces_is_refused(model_file, tmp_path, scale):
    """The spacing alone scaled (its content box, in world units, left as written): a box of a fraction of a voxel
    inside a volume 2^40 times larger, whose X-ray was one grey (the camera fitted the box); scaled by 3, a box whose
    faces fall between voxels."""
    def scaled(header):
        header["spacing"] = [s * scale for s in header["spacing"]]

    with pytest.raises(FileFormatError, match=r"content .* does not lie on the faces of the volume's voxels"):
        clwave.WaveletVolume.open(crafted(model_file, tmp_path, scaled))


def test_content_boxes_written_at_the_ends_of_the_world_lengths_open(tmp_path):
    """What a writer finds lies on the voxels' faces however large the origin is against the spacing."""
    data = np.zeros((6, 5, 4), np.float32)
    data[1:4, 2, 1:3] = 1
    for spacing, origin in [((1e-6, 1e-6, 1e-6), (1e5, -3e4, 7e3)), ((1.0, 1.0, 1.0), (1e12, 0.0, 0.0)),
                            ((0.3, 0.7, 1.1), (0.1, 0.2, 0.3))]:
        volume = clwave.Volume(data, spacing=spacing, origin=origin)
        clwave.WaveletVolume.from_volume(volume, levels=1).save(tmp_path / "m.clw", overwrite=True)
        np.testing.assert_allclose(clwave.WaveletVolume.open(tmp_path / "m.clw").content, volume.content_box())


@pytest.mark.parametrize("suffix", [".nii", ".nii.gz"])
def test_a_nifti_whose_voxels_start_inside_its_header_is_refused(tmp_path, capsys, suffix):
    """vox_offset 0 in a .nii: nibabel (which refuses 1 to 351) read the header's own bytes as the first voxels, and
    the volume was rendered, silently wrong (a mutation of any valid file's field)."""
    import nibabel as nib

    data = np.arange(4 * 5 * 6, dtype=np.int16).reshape(4, 5, 6)
    nib.save(nib.Nifti1Image(data, np.eye(4)), tmp_path / "v.nii")
    content = bytearray((tmp_path / "v.nii").read_bytes())
    assert struct.unpack_from("<f", content, 108) == (352.0,)
    struct.pack_into("<f", content, 108, 0.0)
    (tmp_path / f"w{suffix}").write_bytes(gzip.compress(bytes(content)) if suffix == ".nii.gz" else bytes(content))
    assert_refused_in_one_line(capsys, tmp_path / f"w{suffix}", r"its vox_offset 0 puts its voxels inside its 352-byte "
                                                                r"header")
    np.testing.assert_array_equal(clwave.load(tmp_path / "v.nii").data.shape, (6, 5, 4))  # as written: read


def test_an_hdf5_volume_of_tiny_chunks_is_refused_before_it_is_read(tmp_path, capsys):
    """A 64³ uint8 volume (256 KiB) stored in 1-voxel chunks: HDF5 keeps about 4 KB for each chunk a read spans, and
    its 262,144 took the render past 3.3 GB, refused as "truncated or corrupt" ("memory allocation failed for
    chunk") under a 4 GiB address-space limit. 40³ in 1-voxel chunks (64,000) is refused; in 4³ chunks, read."""
    import h5py

    data = np.arange(40 ** 3, dtype=np.uint32).reshape(40, 40, 40).astype(np.uint8)
    for edge in (1, 4):
        with h5py.File(tmp_path / f"c{edge}.h5", "w") as fh:
            fh.create_dataset("vol", data=data, chunks=(edge,) * 3)
    with pytest.raises(FileFormatError, match=r"its chunks of 1 x 1 x 1 voxels, 64,000 of them, are too small"):
        clwave.load(tmp_path / "c1.h5")
    code, out, err = run(capsys, "info", str(tmp_path / "c1.h5"))
    assert code == 2 and len(err.strip().splitlines()) == 1 and "h5repack" in err, err
    np.testing.assert_array_equal(clwave.load(tmp_path / "c4.h5", chunks=False).data, data)


def test_a_zarr_store_whose_metadata_is_no_node_is_one_line(tmp_path, capsys):
    """A v3 array whose zarr.json is a JSON object of no Zarr node: zarr takes the store for an implicit group and
    warned (ZarrUserWarning, two lines) that its chunk folder is no node, before clwave's one line."""
    import zarr

    zarr.create_array(tmp_path / "v.zarr", data=np.ones((4, 5, 6), np.float32), chunks=(2, 5, 6), zarr_format=3)
    (tmp_path / "v.zarr" / "zarr.json").write_text('{"attributes": {}}')
    assert_refused_in_one_line(capsys, tmp_path / "v.zarr", r"holds no 3-D/4-D arrays \(its arrays: none\)")
