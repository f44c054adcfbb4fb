"""TIFF stacks and folders of TIFF slices read chunk by chunk (docs/chunked.md §1) equal the written voxels and the
whole read; inputs with no spacing warn as NRRD's do; a 3-D stack written as channels reads as slices; a hostile
TIFF is refused before anything is allocated."""

import json
import pickle
import warnings

import numpy as np
import pytest
import tifffile
from PIL import Image

from clwave.cli import main
from clwave.device.memory import HostMemoryError
from clwave.errors import ClwaveWarning, FileFormatError, InputError
from clwave.io.loaders import load, shared

SHAPE = (9, 20, 22)
NO_SPACING = "no spacing in the file"


@pytest.fixture
def volume(rng):
    return rng.integers(0, 65535, SHAPE).astype(np.uint16)


def _plain(tmp_path, a):
    tifffile.imwrite(tmp_path / "v.tif", a, photometric="minisblack")
    return tmp_path / "v.tif", a


def _imagej(tmp_path, a):
    tifffile.imwrite(tmp_path / "v.tif", a, imagej=True, resolution=(0.2, 0.2),
                     metadata={"axes": "ZYX", "spacing": 10.0, "unit": "um"})
    return tmp_path / "v.tif", a


def _ome_two_channels(tmp_path, a):
    data = np.stack([a, a // 2], axis=1)  # ZCYX
    tifffile.imwrite(tmp_path / "v.ome.tif", data, photometric="minisblack", metadata={
        "axes": "ZCYX", "PhysicalSizeZ": 10.0, "PhysicalSizeY": 5.0, "PhysicalSizeX": 5.0})
    return tmp_path / "v.ome.tif", np.moveaxis(data, 1, -1)


def _rgb(tmp_path, a):
    data = (np.stack([a, a >> 3, a >> 5], axis=-1) & 255).astype(np.uint8)
    tifffile.imwrite(tmp_path / "v.tif", data, photometric="rgb")
    return tmp_path / "v.tif", data


def _deflate_strips(tmp_path, a):  # compressed, several strips a page: each strip decoded as a whole
    tifffile.imwrite(tmp_path / "v.tif", a, photometric="minisblack", compression="zlib", rowsperstrip=3)
    return tmp_path / "v.tif", a


def _deflate_tiles(tmp_path, a):
    tifffile.imwrite(tmp_path / "v.tif", np.pad(a, ((0, 0), (0, 12), (0, 10))), photometric="minisblack",
                     compression="zlib", tile=(16, 16))
    return tmp_path / "v.tif", np.pad(a, ((0, 0), (0, 12), (0, 10)))


def _pages_one_at_a_time(tmp_path, a):  # one series a page
    for page in a:
        tifffile.imwrite(tmp_path / "v.tif", page, append=True, photometric="minisblack")
    return tmp_path / "v.tif", a


def _tiff_slices(tmp_path, a):
    (tmp_path / "slices").mkdir()
    for z, page in enumerate(a):
        tifffile.imwrite(tmp_path / "slices" / f"s{z}.tif", page, compression="zlib")
    return tmp_path / "slices", a


WRITERS = {"plain": _plain, "imagej": _imagej, "ome-2-channels": _ome_two_channels, "rgb": _rgb,
           "deflate-strips": _deflate_strips, "deflate-tiles": _deflate_tiles, "pages": _pages_one_at_a_time,
           "slices": _tiff_slices}


@pytest.mark.parametrize("write", WRITERS.values(), ids=WRITERS.keys())
def test_a_tiff_chunked_equals_the_written_voxels_and_the_whole_read(tmp_path, volume, write, monkeypatch):
    path, written = write(tmp_path, volume)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ClwaveWarning)  # no spacing in some: their own test
        whole = load(path, chunks=False)
        np.testing.assert_array_equal(whole.data, written.astype(np.float32))
        for chunks in (4, "auto"):
            vol = load(path, chunks=chunks)
            assert vol.chunked and vol.data.dtype == np.float32
            np.testing.assert_array_equal(vol.data.compute(), whole.data)
            assert (vol.spacing, vol.origin, vol.channels) == (whole.spacing, whole.origin, whole.channels)
        # a graph pickles and computes elsewhere (process-based schedulers): it holds no open file
        np.testing.assert_array_equal(pickle.loads(pickle.dumps(load(path, chunks=5).data)).compute(), whole.data)
        assert not load(path).chunked                                  # small: whole by default, as before
        monkeypatch.setattr(shared, "CHUNKED_MIN_BYTES", written.size * 4)
        assert load(path).chunked                                      # as big as the threshold: chunked


def test_auto_chunks_are_slabs_of_whole_pages(tmp_path, volume, monkeypatch):
    """A page is tifffile's chunk (decoded whole): "auto" reads slabs of whole pages, each page once."""
    path, _ = _plain(tmp_path, volume)
    monkeypatch.setattr(shared, "CHUNK_BYTES", 4 * 20 * 22 * 3)
    assert load(path, chunks="auto").data.chunks == ((3, 3, 3), (20,), (22,))


def test_a_chunk_is_read_when_computed_and_a_cut_file_is_one_line(tmp_path, volume):
    path, _ = _plain(tmp_path, volume)
    data = path.read_bytes()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ClwaveWarning)
        vol = load(path, chunks=4)
        path.write_bytes(data[:len(data) // 2])  # cut after it was opened: its last pages are gone
        with pytest.raises(FileFormatError, match=r"^cannot read .*v\.tif: .*truncated or corrupt$"):
            vol.data.compute()


def test_a_hostile_tiff_is_refused_before_anything_is_allocated(tmp_path):
    """Pages that declare 2^20 x 2^20 samples in one strip (2 TiB each) in a file of a few kB: refused whole
    (the volume) and chunk by chunk (one strip, which tifffile decodes whole), by their declared sizes."""
    path = tmp_path / "h.tif"
    tifffile.imwrite(path, np.ones((4, 32, 32), np.uint16), photometric="minisblack")
    with tifffile.TiffFile(path, mode="r+b") as tif:
        for page in tif.pages:
            for tag in ("ImageLength", "ImageWidth", "RowsPerStrip"):
                page.tags[tag].overwrite(1 << 20)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ClwaveWarning)
        with pytest.raises(HostMemoryError, match=r"reading .*h\.tif whole \(4 x 1048576 x 1048576 uint16\)"):
            load(path, chunks=False)
        for chunks in (None, "auto", 64):
            with pytest.raises(HostMemoryError, match=r"^one 1 x 1048576 x 1048576 uint16 page, strip or tile of "
                                                      r".*h\.tif .*write the TIFF in smaller strips or tiles$"):
                load(path, chunks=chunks)


def test_chunks_are_refused_for_slices_tifffile_does_not_read(tmp_path, volume):
    (tmp_path / "png").mkdir()
    for z, page in enumerate(volume):
        Image.fromarray((page >> 8).astype(np.uint8)).save(tmp_path / "png" / f"s{z}.png")
    with pytest.raises(InputError, match="not to a png-folder input"):
        load(tmp_path / "png", chunks=4)
    assert load(tmp_path / "png", spacing=1).shape == SHAPE


def test_no_spacing_in_a_tiff_or_a_folder_of_slices_is_one_warning(tmp_path, volume):
    """As NRRD's unknown spacing: one warning naming --spacing, none where a spacing was given or the file has
    one (ImageJ calibration, OME PhysicalSize)."""
    (tmp_path / "png").mkdir()
    Image.fromarray(volume[0].astype(np.uint8)).save(tmp_path / "png" / "s0.png")
    Image.fromarray(volume[1].astype(np.uint8)).save(tmp_path / "png" / "s1.png")
    tifffile.imwrite(tmp_path / "plain.tif", volume, photometric="minisblack", resolution=(72.0, 72.0))
    tifffile.imwrite(tmp_path / "ij.tif", volume, imagej=True, metadata={"axes": "ZYX"})  # uncalibrated
    tifffile.imwrite(tmp_path / "o.ome.tif", volume, ome=True, metadata={"axes": "ZYX"})
    _tiff_slices(tmp_path, volume)
    for name in ("png", "plain.tif", "ij.tif", "o.ome.tif", "slices"):
        for chunks in (False, 4) if name != "png" else (False,):
            with pytest.warns(ClwaveWarning) as caught:
                vol = load(tmp_path / name, chunks=chunks)
            files = "s" if name in ("png", "slices") else ""
            assert [str(w.message) for w in caught] == [f"{tmp_path / name}: {NO_SPACING}{files}: 1, 1, 1 assumed; "
                                                        "give spacing= (--spacing DZ,DY,DX)"], name
            assert vol.spacing == (1.0, 1.0, 1.0)
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                assert load(tmp_path / name, spacing=(10, 5, 5), chunks=chunks).spacing == (10.0, 5.0, 5.0)
    _imagej(tmp_path, volume)
    tifffile.imwrite(tmp_path / "sized.ome.tif", volume, ome=True, metadata={"axes": "ZYX", "PhysicalSizeZ": 10.0})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert load(tmp_path / "v.tif").spacing == (10.0, 5.0, 5.0)
        assert load(tmp_path / "sized.ome.tif").spacing == (10.0, 1.0, 1.0)  # the others: 1 micrometre, logged


def test_no_spacing_warning_on_the_command_line(tmp_path, volume, capsys):
    _tiff_slices(tmp_path, volume)
    assert main(["compress", str(tmp_path / "slices"), "-o", str(tmp_path / "a.clw")]) == 0
    err = capsys.readouterr().err
    assert err.count(f"clwave: warning: {tmp_path / 'slices'}: {NO_SPACING}s: 1, 1, 1 assumed; give spacing= "
                     "(--spacing DZ,DY,DX)") == 1
    assert main(["compress", str(tmp_path / "slices"), "--spacing", "10,5,5", "-o", str(tmp_path / "b.clw")]) == 0
    assert NO_SPACING not in capsys.readouterr().err


@pytest.mark.parametrize("options", [dict(imagej=True), dict(ome=True)], ids=["imagej", "ome"])
def test_a_3d_stack_written_without_axes_is_read_as_slices(tmp_path, volume, options, capsys):
    """``tifffile.imwrite(path, volume, imagej=True)`` (or ``ome=True``) of a 3-D array with no ``axes`` writes
    'CYX': more channels than clwave models and no z axis are a Z stack, read as one with a warning naming the
    rewrite that says so (trial24: it was refused as 9 channels, suggesting to keep 4)."""
    tifffile.imwrite(tmp_path / "v.tif", volume, **options)
    with tifffile.TiffFile(tmp_path / "v.tif") as tif:
        assert tif.series[0].axes == "CYX"
    for chunks in (False, 4):
        with pytest.warns(ClwaveWarning, match=r"axes 'CYX' .* 9 channels and no z axis, .* read as 9 slices "
                                               r"\(a Z stack\): write it with metadata=\{'axes': 'ZYX'\} to say so"):
            vol = load(tmp_path / "v.tif", chunks=chunks)
        np.testing.assert_array_equal(np.asarray(vol.data), volume.astype(np.float32))
    assert main(["compress", str(tmp_path / "v.tif"), "-o", str(tmp_path / "v.clw")]) == 0
    assert "read as 9 slices" in capsys.readouterr().err
    small = volume[:3]  # 3 channels of a 2-D image are its colour, not slices: refused as no volume
    tifffile.imwrite(tmp_path / "c3.tif", small, **options)
    with pytest.raises(FileFormatError, match="one 2-D image"):
        load(tmp_path / "c3.tif")


def test_chunked_and_whole_compress_of_a_tiff_write_the_same_model(tmp_path, volume, capsys):
    """The same file, but for what only a whole read measures and records in the header: the model's error and the
    input's noise (docs/chunked.md §4).  Every dataset is the whole file's bit for bit, with its type, chunks and
    filters, every other attribute equal, and the header the whole one's without those two figures."""
    import h5py

    path, _ = _imagej(tmp_path, volume)
    for chunks in ("off", "6"):
        assert main(["compress", str(path), "--chunks", chunks, "--subtract", "100", "-o",
                     str(tmp_path / f"{chunks}.clw")]) == 0, capsys.readouterr().err
    with h5py.File(tmp_path / "off.clw", "r") as whole, h5py.File(tmp_path / "6.clw", "r") as chunked:
        measured = json.loads(whole.attrs["header"])
        assert measured.pop("model_error") > 0 and measured["noise_sigma"] is not None
        assert json.loads(chunked.attrs["header"]) == dict(measured, noise_sigma=None)  # null: not measured
        assert sorted(whole.attrs) == sorted(chunked.attrs)
        assert all(np.array_equal(whole.attrs[k], chunked.attrs[k]) for k in whole.attrs
                   if k not in ("header", "header_crc32"))
        names = []
        whole.visit(names.append)
        chunked_names = []
        chunked.visit(chunked_names.append)
        assert names == chunked_names
        for name in names:
            a, b = whole[name], chunked[name]
            assert isinstance(a, h5py.Dataset) == isinstance(b, h5py.Dataset), name
            if isinstance(a, h5py.Dataset):
                assert (a.dtype, a.shape, a.chunks, a.compression, a.shuffle, a.fletcher32) == \
                       (b.dtype, b.shape, b.chunks, b.compression, b.shuffle, b.fletcher32), name
                assert a[()].tobytes() == b[()].tobytes(), name
            assert sorted(a.attrs) == sorted(b.attrs) and all(
                np.array_equal(a.attrs[k], b.attrs[k]) for k in a.attrs), name


def test_pages_of_a_codec_tifffile_cannot_decode_here_are_named(tmp_path, volume):
    """LZW (Fiji's, Pillow's) needs imagecodecs, which clwave does not install: one line naming it, whole or
    chunked, in a file or a folder of slices (it said "truncated or corrupt")."""
    import tifffile.tifffile as tf

    if tf.COMPRESSION.LZW in tifffile.TIFF.DECOMPRESSORS:
        pytest.skip("imagecodecs is installed here: LZW is decoded")
    (tmp_path / "lzw").mkdir()
    images = [Image.fromarray((page >> 8).astype(np.uint8)) for page in volume[:3]]
    for z, image in enumerate(images):
        image.save(tmp_path / "lzw" / f"s{z}.tif", compression="tiff_lzw")
    images[0].save(tmp_path / "stack.tif", compression="tiff_lzw", save_all=True, append_images=images[1:])
    for path, chunks in ((tmp_path / "lzw", False), (tmp_path / "lzw", 4), (tmp_path / "stack.tif", False),
                        (tmp_path / "stack.tif", 4)):
        with pytest.raises(FileFormatError, match=r"holds LZW-compressed pages, which tifffile decodes only with the "
                                                  r"imagecodecs package: install it"):
            load(path, chunks=chunks, spacing=1)
