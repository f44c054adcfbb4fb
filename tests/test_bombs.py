"""Decompression bombs (bomb28; docs/known-gaps.md §15): a compressed input whose stream inflates far past the size
its header declares is refused while it is decompressed, in one line, its memory bounded by the declared size (a
child process under an address-space limit), and a stream of the declared size is read as written."""

import bz2
import gzip
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
from clwave.io.loaders import load
mapped = next(int(line.split()[1]) * 1024 for line in open("/proc/self/status") if line.startswith("VmSize:"))
resource.setrlimit(resource.RLIMIT_AS, (mapped + {headroom}, resource.RLIM_INFINITY))
try:
    load(sys.argv[1], orientation=None)
except Exception as exc:
    print(type(exc).__name__, exc)
"""


def load_bounded(path) -> str:
    """The error (its type and line) of loading ``path`` in a child that may map only ``HEADROOM`` more bytes."""
    done = subprocess.run([sys.executable, "-c", _CHILD.format(headroom=HEADROOM), str(path)], capture_output=True,
                          text=True, timeout=60)
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
    "the file may be truncated or corrupt"; now refused one byte past the declared 960."""
    assert load_bounded(nrrd_bombs / name) == (
        f"FileFormatError {nrrd_bombs / name}: its {encoding} stream holds more than the 960 bytes its header "
        "declares (6 x 10 x 8 voxels); its header is wrong or the file is not what it says")


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
