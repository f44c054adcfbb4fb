"""FreeSurfer MGH and MGZ volumes (``.mgh``, ``.mgz``): written here by nibabel's writer, read by clwave; each voxel
is compared with the voxel nibabel's affine puts at its world position, never with clwave's own orientation code
(docs/coordinates.md §1)."""

import gzip
import struct

import nibabel as nib
import numpy as np
import pytest
from nibabel.freesurfer.mghformat import MGHImage

import clwave
from clwave.errors import ClwaveWarning, FileFormatError, InputError
from clwave.io.loaders import describe
from test_cli import run
from test_labels import APARC_ASEG, atlas_map

#: FreeSurfer's conformed orientation (LIA: i to the left, j down, k forward), 1 mm, and one with voxels of 2, 3, 4
#: mm along permuted, flipped axes
LIA = np.array([[-1.0, 0, 0, 128], [0, 0, 1, -128], [0, -1, 0, 128], [0, 0, 0, 1]])
PERMUTED = np.array([[0, 0, -4.0, 30], [2.0, 0, 0, -7], [0, 3.0, 0, 5], [0, 0, 0, 1]])


def _save(path, data, affine):
    nib.save(MGHImage(data, affine), path)
    return path


def assert_placed_as_nibabel_places_it(vol, data_ijk, affine):
    """Every voxel of ``vol`` holds the voxel of ``data_ijk`` that ``affine`` puts at its world position."""
    index = np.indices(vol.shape).reshape(3, -1).T.astype(float)
    world = vol.voxel_to_world(index)  # (x, y, z) of each voxel (z, y, x)
    ijk = np.linalg.solve(affine[:3, :3], (world - affine[:3, 3]).T).T
    np.testing.assert_allclose(ijk, np.rint(ijk), atol=1e-4)
    i, j, k = np.rint(ijk).astype(int).T
    np.testing.assert_array_equal(vol.data.reshape(-1), data_ijk[i, j, k].astype(np.float32))


@pytest.mark.parametrize("suffix", [".mgh", ".mgz"])
@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.int32, np.float32])
@pytest.mark.parametrize("affine", [LIA, PERMUTED], ids=["LIA", "permuted"])
def test_an_mgh_volume_is_placed_in_ras_by_its_affine(tmp_path, rng, suffix, dtype, affine):
    data = rng.integers(0, 200, (5, 6, 7)).astype(dtype)
    vol = clwave.load(_save(tmp_path / f"v{suffix}", data, affine))
    assert_placed_as_nibabel_places_it(vol, data, affine)
    columns = np.linalg.norm(affine[:3, :3], axis=0)  # the voxel size along i, j, k
    assert sorted(vol.spacing) == sorted(columns) and vol.unit == "mm" and vol.obliquity == 0.0
    centre = affine @ np.append((np.array(data.shape) - 1) / 2, 1)
    np.testing.assert_allclose(vol.origin, centre[:3])
    facts = describe(tmp_path / f"v{suffix}")
    assert facts["format"] == "mgh" and facts["shape"] == list(vol.shape)
    np.testing.assert_allclose(facts["spacing"], vol.spacing)
    np.testing.assert_allclose(facts["origin"], vol.origin)


def test_a_large_mgh_is_read_chunk_by_chunk_as_whole_and_a_mgz_is_not(tmp_path, rng, capsys):
    data = rng.normal(size=(9, 10, 11)).astype(np.float32)
    path = _save(tmp_path / "v.mgh", data, PERMUTED)
    chunked, whole = clwave.load(path, chunks=4), clwave.load(path)
    assert hasattr(chunked.data, "dask") and isinstance(whole.data, np.ndarray)
    np.testing.assert_array_equal(np.asarray(chunked.data), whole.data)
    zipped = _save(tmp_path / "v.mgz", data, PERMUTED)
    with pytest.raises(InputError, match=r"not to a \.mgz file \(gzip cannot seek: gunzip it into a \.mgh first\)"):
        clwave.load(zipped, chunks=4)
    code, out, err = run(capsys, "info", str(zipped))
    assert code == 0 and "mgh" in out and "mm (x, y, z; --spacing 3,2,4), centre" in out and "(RAS+)" in out, err


def test_an_mgh_without_geometry_is_freesurfers_default_with_a_warning(tmp_path, rng):
    """goodRASFlag 0: coronal LIA, 1 mm voxels, the centre of the (dims / 2) voxel at the origin, as FreeSurfer reads
    it."""
    data = rng.integers(0, 9, (4, 5, 6)).astype(np.uint8)
    image = MGHImage(data, PERMUTED)
    image.header["goodRASFlag"] = 0
    raw = image.header.binaryblock + b"\0" * (284 - len(image.header.binaryblock)) + data.astype(">u1").tobytes("F")
    (tmp_path / "plain.mgh").write_bytes(raw)
    with pytest.warns(ClwaveWarning, match="no valid geometry .goodRASFlag 0.: FreeSurfer's default"):
        vol = clwave.load(tmp_path / "plain.mgh")
    # FreeSurfer's (mriio.cpp: x_r = -1, y_s = -1, z_a = 1, c_ras 0, 1 mm; not nibabel's, LSP), its centre at dims / 2
    default = np.array([[-1.0, 0, 0, 2], [0, 0, 1, -3], [0, -1, 0, 2.5], [0, 0, 0, 1]])
    assert_placed_as_nibabel_places_it(vol, data, default)
    np.testing.assert_allclose(vol.origin, (0.5, -0.5, 0.5))  # MGH centres dims / 2, voxels at their corners


def test_frames_are_refused_as_a_time_series_and_described(tmp_path, rng, capsys):
    data = rng.normal(size=(4, 5, 6, 3)).astype(np.float32)
    image = MGHImage(data, LIA)
    image.header["tr"] = 2000.0
    nib.save(image, tmp_path / "bold.mgz")
    with pytest.raises(FileFormatError, match="holds 3 frames of 4 x 5 x 6 voxels; .* pick one, frame=K for K in 0 "
                                              r"\.\. 2"):
        clwave.load(tmp_path / "bold.mgz")
    facts = describe(tmp_path / "bold.mgz")
    assert facts["time"] == dict(points=3, step=2000.0, unit="ms", along="time", frame=None)
    assert facts["shape"] == [5, 6, 4]  # z: j, y: k, x: i


def _header(dims=(2, 3, 4, 1), code=1, version=1):
    image = MGHImage(np.zeros((2, 3, 4), np.int32), np.eye(4))
    block = bytearray(image.header.binaryblock.ljust(284, b"\0"))
    block[:24] = struct.pack(">6i", version, *dims, code)
    return bytes(block)


# gzip streams of mtime 0: the same bytes, so the same test ids, in every process (pytest-xdist's workers)
@pytest.mark.parametrize("name, content, words", [
    ("short.mgh", _header()[:60], r"its MGH header is cut short \(60 of 90 bytes\); the file is truncated"),
    ("cut.mgh", _header() + b"\0" * 50, r"declares 2 x 3 x 4 voxels \(96 bytes\) but the file holds 50 bytes"),
    ("lying.mgz", gzip.compress(_header((200, 300, 400, 1)) + b"\0" * 96, mtime=0),
     "but its gzip stream holds 96 bytes"),
    ("wraps.mgh", _header((1 << 30, 3, 4, 1)) + b"\0" * 96, "declares 1073741824 x 3 x 4 voxels"),
    ("cut.mgz", gzip.compress(_header() + bytes(range(96)), mtime=0)[:-30], "truncated"),
    ("plain.mgz", _header() + b"\0" * 96, r"is not gzip-compressed, .* name it plain\.mgh"),
    ("zipped.mgh", gzip.compress(_header() + b"\0" * 96, mtime=0), r"is gzip-compressed, .* name it zipped\.mgz"),
    ("type.mgh", _header(code=7) + b"\0" * 96, "names the sample type 7, none MGH has"),
    ("empty.mgh", _header((0, 3, 4, 1)) + b"\0" * 96, "declares 0 x 3 x 4 voxels in 1 frame"),
    ("negative.mgh", _header((-3, 3, 4, 1)) + b"\0" * 96, "declares -3 x 3 x 4 voxels"),
    ("version.mgh", _header(version=5) + b"\0" * 96, r"is not an MGH file \(its version field is 5"),
    ("flat.mgh", _header()[:30] + struct.pack(">3f", 0, 0, 0) + _header()[42:] + b"\0" * 96,
     "its vox2ras .* is not finite or not invertible"),
    ("nan.mgh", _header()[:30] + struct.pack(">3f", np.nan, 1, 1) + _header()[42:] + b"\0" * 96,
     "is not finite or not invertible")])
def test_a_truncated_or_lying_mgh_is_refused_in_one_line(tmp_path, capsys, name, content, words):
    (tmp_path / name).write_bytes(content)
    assert_refused_in_one_line(capsys, tmp_path / name, words)


def assert_refused_in_one_line(capsys, path, words):
    """``load`` refuses ``path`` with one line matching ``words``, and ``clwave info`` with one line, exit 2."""
    with pytest.raises(FileFormatError, match=words) as excinfo:
        clwave.load(path)
    assert "\n" not in str(excinfo.value)
    code, out, err = run(capsys, "info", str(path))
    assert code == 2 and len(err.strip().splitlines()) == 1 and not out, err


def test_an_aparc_aseg_mgz_is_a_label_map(tmp_path, capsys):
    """FreeSurfer's aparc+aseg.mgz (int32, 108 labels up to 2035) is told as a label map: compressing it with the
    default cubic wavelet is warned of, naming Haar."""
    path = _save(tmp_path / "aparc+aseg.mgz", atlas_map(APARC_ASEG).astype(np.int32), LIA)
    assert clwave.load(path).labels
    code, out, err = run(capsys, "compress", str(path), "--levels", "1", "-o", str(tmp_path / "a.clw"))
    assert code == 0 and err.count("label map") == 1 and "--wavelet haar" in err, err
