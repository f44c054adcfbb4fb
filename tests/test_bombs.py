"""Decompression bombs (bomb28; docs/known-gaps.md §15): a compressed input whose stream inflates far past the size
its header declares is refused while it is decompressed, in one line, its memory bounded by the declared size (a
child process under an address-space limit), and a stream of the declared size is read as written."""

import bz2
import gzip
import lzma
import os
import struct
import subprocess
import sys

import numpy as np
import pytest

import clwave
from clwave.errors import FileFormatError

#: what the child may map beyond what it has mapped when it starts reading: less than any bomb below inflates to
HEADROOM = 256 << 20

#: a bomb's decompressed length: twice the headroom
BOMB = 512 << 20

_CHILD = """
import resource, sys
import numpy as np
from clwave.io.loaders import describe, load
mapped = next(int(line.split()[1]) * 1024 for line in open("/proc/self/status") if line.startswith("VmSize:"))
resource.setrlimit(resource.RLIMIT_AS, (mapped + {headroom}, resource.RLIM_INFINITY))
for call in sys.argv[2:]:
    try:
        np.asarray(load(sys.argv[1], orientation=None).data) if call == "load" else describe(sys.argv[1])
    except Exception as exc:
        print(type(exc).__name__, exc)
"""


def load_bounded(path, *calls) -> str:
    """The error (its type and line) of loading ``path`` (or describing it, ``clwave info``'s read: ``calls``
    ("load", "describe"), a line each, one after the other) in a child that may map only ``HEADROOM`` more bytes
    than it had mapped when it started."""
    done = subprocess.run([sys.executable, "-c", _CHILD.format(headroom=HEADROOM), str(path), *(calls or ["load"])],
                          capture_output=True, text=True, timeout=60,
                          env=os.environ | {"MALLOC_ARENA_MAX": "2"})  # glibc's 64 MiB of address space a thread
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def _gzip_bomb():
    return gzip.compress(bytes(BOMB), 1)


HEAD = b"NRRD0004\ntype: short\ndimension: 3\nsizes: 8 10 6\nendian: little\nencoding: %s\n%s\n"
VOXELS = np.arange(480, dtype="<i2")  # 960 bytes


@pytest.fixture(scope="module")
def nrrd_bombs(tmp_path_factory):
    """Attached NRRDs of the 960 bytes declared whose stream holds ``BOMB`` bytes: a gzip stream of two members,
    the bomb first (the trailer, the second member's, says 960: pynrrd inflated the first, 512 MiB, before it
    compared), and a bzip2 stream (its size was never checked)."""
    folder = tmp_path_factory.mktemp("bombs")
    (folder / "members.nrrd").write_bytes(HEAD % (b"gzip", b"") + _gzip_bomb() + gzip.compress(VOXELS.tobytes()))
    (folder / "bzip2.nrrd").write_bytes(HEAD % (b"bzip2", b"") + bz2.compress(bytes(BOMB), 9))
    return folder


@pytest.mark.parametrize("name, encoding", [("members.nrrd", "gzip"), ("bzip2.nrrd", "bzip2")])
def test_a_nrrd_stream_inflating_past_its_declared_size_is_refused_while_it_is_decompressed(nrrd_bombs, name,
                                                                                            encoding):
    """Before: 2.1 GB peak for a 1 GiB bomb (a gzip stream of two members, 1 MB; a bzip2 stream, 849 bytes), then
    "the file may be truncated or corrupt"; now refused one byte past the declared 960, by ``clwave info`` too (which
    described it until loose30: its stream decompressed and weighed as the read's, kept nowhere)."""
    assert load_bounded(nrrd_bombs / name, "load", "describe").splitlines() == [
        f"FileFormatError {nrrd_bombs / name}: its {encoding} stream holds more than the 960 bytes its header "
        "declares (6 x 10 x 8 voxels); its header is wrong or the file is not what it says"] * 2


def _compressed(encoding, data):
    return gzip.compress(data) if encoding == "gzip" else bz2.compress(data)


@pytest.mark.parametrize("encoding", ["gzip", "bzip2"])
def test_a_compressed_nrrd_is_read_to_its_declared_size_and_no_further(tmp_path, encoding):
    """The declared bytes read as written (every gzip member; a ``byte skip`` counts bytes of the stream, as Teem
    reads it, and a ``line skip`` lines before it); one byte more or less is refused in one line."""
    expected = VOXELS.reshape(6, 10, 8)
    body = VOXELS.tobytes()
    cases = {"plain": (b"", _compressed(encoding, body)),
             "members": (b"", _compressed(encoding, body[:333]) + _compressed(encoding, body[333:])),
             "skips": (b"byte skip: 5\nline skip: 2\n", b"one\ntwo\n" + _compressed(encoding, bytes(5) + body))}
    for name, (fields, stream) in cases.items():
        (tmp_path / f"{name}.nrrd").write_bytes(HEAD % (encoding.encode(), fields) + stream)
        read = clwave.load(tmp_path / f"{name}.nrrd", orientation=None).data
        np.testing.assert_array_equal(read, expected, err_msg=name)
    (tmp_path / "long.nrrd").write_bytes(HEAD % (encoding.encode(), b"") + _compressed(encoding, body + b"\1"))
    more = "961 bytes or more, more" if encoding == "gzip" else "more"  # a gzip trailer tells, before the read
    with pytest.raises(FileFormatError, match=f"its {encoding} stream holds {more} than the 960 bytes"):
        clwave.load(tmp_path / "long.nrrd")
    (tmp_path / "short.nrrd").write_bytes(HEAD % (encoding.encode(), b"") + _compressed(encoding, body[:-1]))
    with pytest.raises(FileFormatError, match=r"declares 6 x 10 x 8 voxels \(960 bytes\) but its .* 959 bytes"):
        clwave.load(tmp_path / "short.nrrd")


@pytest.fixture(scope="module")
def nifti_bomb(tmp_path_factory):
    """A ``.nii.gz`` of 8^3 voxels whose extension flag is set and whose ``vox_offset`` puts them past an extension
    of ``BOMB`` bytes of zeros (a 512 KiB file): nibabel reads every extension whole before clwave sees the header."""
    import struct

    import nibabel as nib

    folder = tmp_path_factory.mktemp("nifti")
    nib.save(nib.Nifti1Image(np.arange(512, dtype=np.uint8).reshape(8, 8, 8), np.eye(4)), folder / "s.nii")
    raw = (folder / "s.nii").read_bytes()
    header = bytearray(raw[:348])
    struct.pack_into("<f", header, 108, 352 + BOMB + 32)  # a float32 exactly
    extension = b"\1\0\0\0" + struct.pack("<ii", BOMB + 32, 0) + bytes(BOMB + 24)
    (folder / "ext.nii.gz").write_bytes(gzip.compress(bytes(header) + extension + raw[352:], 1))
    return folder / "ext.nii.gz"


def test_a_nifti_extension_past_what_clwave_weighs_is_refused_before_nibabel_reads_it(nifti_bomb, tmp_path):
    """Before: 1.2 GB peak for a 1 GiB extension (nibabel's warning, then "read length must be non-negative"); now
    refused by its header, and a file with a small extension is read."""
    import nibabel as nib

    assert load_bounded(nifti_bomb) == (
        f"FileFormatError {nifti_bomb}: its vox_offset {352 + BOMB + 32:,} declares {BOMB + 32:,} bytes of "
        "NIfTI extensions, more than the 67,108,864 clwave lets nibabel read (it reads them whole, and clwave uses "
        "none): remove them (nibabel: image.header.extensions.clear(), then save)")
    image = nib.Nifti1Image(np.arange(512, dtype=np.int16).reshape(8, 8, 8), np.eye(4))
    image.header.extensions.append(nib.nifti1.Nifti1Extension("comment", b"a small one"))
    nib.save(image, tmp_path / "small.nii.gz")
    np.testing.assert_array_equal(clwave.load(tmp_path / "small.nii.gz", orientation=None).data,
                                  np.arange(512).reshape(8, 8, 8).transpose(2, 1, 0))


def _deflated(ds, tail=b"", zeros=0) -> bytes:
    """``ds`` as a deflated DICOM file, its dataset followed by ``tail`` and ``zeros`` zero bytes in the stream."""
    import io
    import zlib

    import pydicom
    from pydicom.uid import DeflatedExplicitVRLittleEndian

    body = pydicom.filebase.DicomBytesIO()
    body.is_little_endian, body.is_implicit_VR = True, False
    pydicom.filewriter.write_dataset(body, ds)
    deflater = zlib.compressobj(9, zlib.DEFLATED, -zlib.MAX_WBITS)
    stream = deflater.compress(body.getvalue() + tail)
    stream += b"".join(deflater.compress(bytes(1 << 24)) for _ in range(zeros >> 24)) + deflater.flush()
    ds.file_meta.TransferSyntaxUID = DeflatedExplicitVRLittleEndian
    head = io.BytesIO(b"\0" * 128 + b"DICM")
    head.seek(132)
    pydicom.filewriter.write_file_meta_info(head, ds.file_meta)
    return head.getvalue() + stream


def test_a_deflated_dicom_slice_inflating_past_its_pixel_data_is_refused_before_pydicom_inflates_it(tmp_path, rng):
    """A series of deflated slices is read as written; one whose stream goes on past its pixel data with a 512 MiB
    element (a 512 KiB file) is refused before pydicom inflates it whole (before: 2.2 GB peak for 1 GiB, then "has
    no SeriesInstanceUID")."""
    import struct

    import pydicom
    from pydicom.uid import generate_uid
    from test_loaders import axial, write_series

    z = [15.0, 10.0, 12.5]
    stored = write_series(tmp_path, rng, axial(*z), generate_uid(), ["a", "b", "c"])
    for name in "abc":
        (tmp_path / name).write_bytes(_deflated(pydicom.dcmread(tmp_path / name)))
    assert pydicom.dcmread(tmp_path / "a").file_meta.TransferSyntaxUID == "1.2.840.10008.1.2.1.99"
    np.testing.assert_array_equal(clwave.load(tmp_path, progress_bar=False).data,
                                  (stored[np.argsort(z)] * 2.0 - 1024)[:, ::-1, ::-1])
    element = struct.pack("<HH", 0x7FE1, 0x0010) + b"OB\0\0" + struct.pack("<I", BOMB)  # after the pixel data
    ds = pydicom.dcmread(tmp_path / "c")
    ds.file_meta.TransferSyntaxUID = pydicom.uid.ExplicitVRLittleEndian
    (tmp_path / "c").write_bytes(_deflated(ds, element, BOMB))
    assert load_bounded(tmp_path) == (
        f"FileFormatError DICOM file {tmp_path / 'c'}: its deflated dataset inflates past 16,777,276 bytes, the 60 of "
        "pixel data its attributes declare and 16,777,216 of others; it is not what it says (a decompression bomb): "
        "move it out of the folder")


def _tiff_strip(path, compression, first):
    """A TIFF stack of 8 pages of 64 x 64 uint8, one strip a page compressed by ``compression``, whose first page's
    strip is the stream ``first`` instead."""
    import tifffile

    tifffile.imwrite(path, np.ones((8, 64, 64), np.uint8), compression=compression, photometric="minisblack",
                     rowsperstrip=64)
    with tifffile.TiffFile(path) as tif:
        tags = tif.pages[0].tags
        offset, count = tags["StripOffsets"].valueoffset, tags["StripByteCounts"].valueoffset
    data = bytearray(path.read_bytes())
    struct.pack_into("<I", data, offset, len(data))  # one strip: its offset and length in the tags themselves
    struct.pack_into("<I", data, count, len(first))
    path.write_bytes(bytes(data + first))


TIFF_CODECS = {"zlib": lambda data: gzip.zlib.compress(data, 1), "lzma": lambda data: lzma.compress(data, preset=0)}


@pytest.mark.parametrize("compression", TIFF_CODECS)
def test_a_tiff_strip_inflating_past_its_size_is_refused_while_it_is_decompressed(tmp_path, compression):
    """A strip of 4,096 bytes whose stream holds ``BOMB`` (2.3 MB, 78 KB): before, tifffile's own decoders (no
    imagecodecs) inflated it whole, 2.2 GB peak for 1 GiB, in ``clwave info`` too (its trial decode of the first
    strip); now each strip is decompressed to its size and refused a byte past it."""
    _tiff_strip(tmp_path / "bomb.tif", compression, TIFF_CODECS[compression](bytes(BOMB)))
    for call in ("describe", "load"):
        assert load_bounded(tmp_path / "bomb.tif", call) == (
            f"FileFormatError cannot read {tmp_path / 'bomb.tif'}: ValueError: a compressed strip or tile inflates "
            "past the 4,096 bytes it holds: it is not what it says (a decompression bomb); the file may be truncated "
            "or corrupt"), call


@pytest.mark.parametrize("compression", TIFF_CODECS)
def test_a_compressed_tiff_is_read_to_each_strips_size_and_no_further(tmp_path, compression):
    """Strips and tiles read as written, whole and chunk by chunk; a strip of one byte more is refused."""
    import tifffile

    volume = np.arange(8 * 64 * 64, dtype=np.uint16).reshape(8, 64, 64)
    tifffile.imwrite(tmp_path / "strips.tif", volume, compression=compression, photometric="minisblack",
                     rowsperstrip=16)
    tifffile.imwrite(tmp_path / "tiles.tif", volume, compression=compression, photometric="minisblack",
                     tile=(16, 16))
    for name in ("strips.tif", "tiles.tif"):
        for chunks in (False, 4):
            np.testing.assert_array_equal(clwave.load(tmp_path / name, orientation=None, chunks=chunks).data,
                                          volume, err_msg=f"{name} {chunks}")
    _tiff_strip(tmp_path / "long.tif", compression, TIFF_CODECS[compression](bytes(64 * 64 + 1)))
    with pytest.raises(FileFormatError, match="a compressed strip or tile inflates past the 4,096 bytes it holds"):
        clwave.load(tmp_path / "long.tif")


def _zarr(path, version, compressor, chunk=None, **options):
    """A Zarr array of 16^3 uint8 in one chunk (``chunk``: those bytes instead of it, stored as they are)."""
    import zarr

    array = zarr.create_array(str(path), shape=(16, 16, 16), chunks=(16, 16, 16), dtype="uint8", zarr_format=version,
                              compressors=compressor, **options)
    array[:] = np.arange(4096).reshape(16, 16, 16) % 251
    if chunk is not None:
        (path / ("0.0.0" if version == 2 else "c/0/0/0")).write_bytes(chunk)
    return path


def _v3(name):
    import zarr.codecs

    return {"gzip": zarr.codecs.GzipCodec(level=1), "zstd": zarr.codecs.ZstdCodec(),
            "blosc": zarr.codecs.BloscCodec()}[name]


ZARR_BOMBS = [(2, "zlib", "inflates past the 4,096 bytes it holds"), (2, "gzip", "inflates past the 4,096 bytes"),
              (2, "bz2", "inflates past the 4,096 bytes"), (2, "blosc", "declares 536,870,912 bytes"),
              (2, "zstd", "declares 536,870,912 bytes"), (2, "lz4", "declares 536,870,912 bytes"),
              (3, "gzip", "inflates past the 4,096 bytes"), (3, "zstd", "declares 536,870,912 bytes"),
              (3, "blosc", "declares 536,870,912 bytes")]


@pytest.mark.parametrize("version, codec, said", ZARR_BOMBS)
def test_a_zarr_chunk_inflating_past_its_size_is_refused_before_it_is_held(tmp_path, version, codec, said):
    """A 16^3 uint8 chunk (4,096 bytes) whose stream holds ``BOMB``: before, numcodecs decoded it whole or allocated
    the size its header states (1.3 GB peak for 1 GiB, then out of memory or "cannot reshape"); now a stream is
    decompressed to the chunk's size and refused a byte past it, a stated size refused before anything is decoded."""
    import numcodecs

    encoder = numcodecs.get_codec({"id": codec, **({"level": 1} if codec in ("zlib", "gzip") else {})})
    path = _zarr(tmp_path / "bomb.zarr", version, encoder if version == 2 else _v3(codec),
                 encoder.encode(np.zeros(BOMB, np.uint8)))
    error = load_bounded(path)
    assert error.startswith(f"FileFormatError cannot read {path}: ValueError: a {codec} chunk {said}"), error
    assert error.endswith("it is not what it says (a decompression bomb); the file may be truncated or corrupt")


def test_zarr_chunks_are_read_to_their_size_and_no_further(tmp_path):
    """Each codec's chunks read as written (v2 with a filter, v3 sharded); a zlib stream of one byte more than its
    chunk, and a Zstandard frame that states no size (numcodecs would grow its buffer), refused."""
    import numcodecs
    import zarr.codecs

    expected = np.arange(4096).reshape(16, 16, 16) % 251
    cases = {f"v2{c}": (2, numcodecs.get_codec({"id": c}), {}) for c in ("zlib", "gzip", "bz2", "lzma", "blosc",
                                                                           "zstd", "lz4")}
    cases |= {f"v3{c}": (3, _v3(c), {}) for c in ("gzip", "zstd", "blosc")}
    cases["v2delta"] = (2, numcodecs.Zlib(), {"filters": [numcodecs.Delta("uint8")]})
    cases["v3shards"] = (3, _v3("gzip"), {"shards": (16, 16, 16), "chunks": (8, 8, 8)})
    for name, (version, compressor, options) in cases.items():
        path = tmp_path / f"{name}.zarr"
        if "chunks" in options:
            zarr.create_array(str(path), shape=(16, 16, 16), dtype="uint8", compressors=compressor,
                              **options)[:] = expected
        else:
            _zarr(path, version, compressor, **options)
        np.testing.assert_array_equal(clwave.load(path, orientation=None).data, expected, err_msg=name)
    long = _zarr(tmp_path / "long.zarr", 2, numcodecs.Zlib(), zlib_compress(bytes(4097)))
    with pytest.raises(FileFormatError, match="a zlib chunk inflates past the 4,096 bytes it holds"):
        np.asarray(clwave.load(long).data)
    frame = numcodecs.Zstd().encode(bytes(4096))
    assert frame[4] >> 5 == 0b011  # a 2-byte content size, a single segment: one with no size and a 4 KiB window
    unsized = frame[:4] + bytes([frame[4] & 0b111, 2 << 3]) + frame[7:]
    np.testing.assert_array_equal(np.frombuffer(numcodecs.Zstd().decode(unsized), np.uint8), np.zeros(4096))
    path = _zarr(tmp_path / "unsized.zarr", 2, numcodecs.Zstd(), unsized)
    with pytest.raises(FileFormatError, match="a zstd chunk does not state its size, where its chunk holds 4,096"):
        np.asarray(clwave.load(path).data)


def zlib_compress(data, level=6):
    return gzip.zlib.compress(data, level)


def _h5(path, chunk=None, **filters):
    """An HDF5 file of one 16^3 uint8 dataset /v in chunks of 16 x 16 x 8 (``chunk``: the first one's stored bytes)."""
    import h5py

    with h5py.File(path, "w") as h5:
        dataset = h5.create_dataset("v", data=np.arange(4096).reshape(16, 16, 16) % 251, dtype=np.uint8,
                                    chunks=(16, 16, 8), **filters)
        if chunk is not None:
            dataset.id.write_direct_chunk((0, 0, 0), chunk)
    return path


def _hdf5_bombs():
    import hdf5plugin
    import numcodecs

    zeros = bytes(BOMB)
    return {"deflate": ({"compression": "gzip"}, lambda: zlib_compress(zeros, 1), "inflates past the 2,048 bytes"),
            "zstd": (dict(hdf5plugin.Zstd()), lambda: numcodecs.Zstd().encode(zeros), "declares 536,870,912 bytes")}


@pytest.mark.parametrize("codec", ["deflate", "zstd"])
def test_an_hdf5_chunk_inflating_past_its_size_is_refused_before_hdf5_decodes_it(tmp_path, codec):
    """A chunk of 2,048 bytes whose stream holds ``BOMB``: before, HDF5's deflate filter grew its buffer as far as
    the stream went (1.3 GB peak for 1 GiB, then "filter returned failure") and hdf5plugin's Zstandard allocated
    what its frame states (1.3 GB, then read); now each chunk a read covers is checked first."""
    filters, bomb, said = _hdf5_bombs()[codec]
    path = _h5(tmp_path / "bomb.h5", bomb(), **filters)
    error = load_bounded(path)
    assert error.startswith(f"FileFormatError cannot read {path}:/v: ValueError: member /v, its chunk at (0, 0, 0): "
                            f"a {codec} chunk {said}"), error


def test_hdf5_chunks_are_read_to_their_size_and_no_further(tmp_path):
    """Each filter's chunks read as written, whole and chunk by chunk; a deflate chunk of one byte more refused."""
    import hdf5plugin

    expected = np.arange(4096).reshape(16, 16, 16) % 251
    cases = {"gzip": {"compression": "gzip", "shuffle": True, "fletcher32": True}, "lzf": {"compression": "lzf"},
             "zstd": dict(hdf5plugin.Zstd(), fletcher32=True), "blosc": dict(hdf5plugin.Blosc())}
    for name, filters in cases.items():
        path = _h5(tmp_path / f"{name}.h5", **filters)
        for chunks in (False, 4):
            np.testing.assert_array_equal(np.asarray(clwave.load(path, orientation=None, chunks=chunks).data),
                                          expected, err_msg=f"{name} {chunks}")
    path = _h5(tmp_path / "long.h5", zlib_compress(bytes(2049)), compression="gzip")
    with pytest.raises(FileFormatError, match=r"its chunk at \(0, 0, 0\): a deflate chunk inflates past the 2,048"):
        np.asarray(clwave.load(path).data)


def _fletcher32(data) -> bytes:
    """HDF5's Fletcher-32 checksum of ``data``, as its filter appends it (a forger's few lines)."""
    words = np.frombuffer(data[:len(data) // 2 * 2], ">u2").astype(np.int64)
    s1 = s2 = 0
    for start in range(0, len(words), 360):
        sums = np.cumsum(words[start:start + 360]) + s1
        s2, s1 = s2 + int(sums.sum()), int(sums[-1])
        s1, s2 = (s1 & 0xFFFF) + (s1 >> 16), (s2 & 0xFFFF) + (s2 >> 16)
    if len(data) % 2:
        s1 += data[-1] << 8
        s2 += s1
        s1, s2 = (s1 & 0xFFFF) + (s1 >> 16), (s2 & 0xFFFF) + (s2 >> 16)
    s1, s2 = (s1 & 0xFFFF) + (s1 >> 16), (s2 & 0xFFFF) + (s2 >> 16)
    return ((s2 << 16) | s1).to_bytes(4, "little")


def test_a_clw_chunk_inflating_past_its_size_is_refused_when_the_file_is_opened(tmp_path, rng):
    """A ``.clw`` whose ``g0/runs`` chunk is a deflate stream of ``BOMB`` behind a forged Fletcher-32: before, read
    (1.24 GB peak for 1 GiB, then "filter returned failure"); now refused when the file is opened, ``clwave info``
    too, every chunk of its datasets weighed by its stored size (more than zlib's bound for the bytes it holds; the
    checksum is HDF5's, checked as it decodes)."""
    import h5py

    volume = clwave.Volume(rng.random((16, 16, 16)).astype(np.float32), spacing=(1, 1, 1))
    path = clwave.WaveletVolume.from_volume(volume, levels=1).save(tmp_path / "v.clw")
    with h5py.File(path, "r+") as h5:
        runs = h5["g0/runs"]
        stream = zlib_compress(bytes(BOMB), 1)
        runs.id.write_direct_chunk((0,) * runs.ndim, stream + _fletcher32(stream))
        most = np.prod(runs.chunks) * runs.dtype.itemsize
    with pytest.raises(FileFormatError, match=rf"member /g0/runs, its chunk at \(0, 0\): a deflate chunk is stored "
                                              rf"in {len(stream):,} bytes, more than the {most:,} bytes it holds "
                                              "take compressed"):
        clwave.WaveletVolume.open(path)
