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
