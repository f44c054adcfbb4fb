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
