"""MRC and CCP4 maps (cryo-EM maps, tomograms, tilt series): written here by ``mrcfile.new``, read by clwave; the
expected volume, spacing and world positions are worked out from the header written, by hand (docs/coordinates.md
§1)."""

import warnings

import mrcfile
import numpy as np
import pytest

import clwave
from clwave.errors import ClwaveWarning
from clwave.io.loaders import describe
from test_cli import run
from test_mgh import assert_refused_in_one_line

VOXEL = (1.25, 2.0, 0.5)  # x, y, z (Å)


def _write(path, stored, voxel=VOXEL, origin=(0.0, 0.0, 0.0), **fields):
    """``stored`` (sections, rows, columns) as an MRC file, then header ``fields`` set as given."""
    with mrcfile.new(path, overwrite=True) as mrc:
        mrc.set_data(stored)
        mrc.voxel_size = voxel
        mrc.header.origin = origin
        for name, value in fields.items():
            setattr(mrc.header, name, value)
    return path


@pytest.mark.parametrize("dtype", [np.int8, np.int16, np.uint16, np.float32, np.float16])
@pytest.mark.parametrize("suffix", [".mrc", ".map", ".rec"])
def test_a_map_is_read_in_angstroms_placed_by_its_origin(tmp_path, rng, dtype, suffix):
    stored = rng.integers(-100 if dtype != np.uint16 else 0, 100, (4, 5, 6)).astype(dtype)
    path = _write(tmp_path / f"map{suffix}", stored, origin=(10.0, -20.0, 30.0))
    vol = clwave.load(path)
    np.testing.assert_array_equal(vol.data, stored.astype(np.float32))  # x fastest: (z, y, x) as stored
    assert vol.spacing == VOXEL[::-1] and vol.unit == "A"
    # the first voxel at the header's origin, each next one a voxel size further along its axis
    corner = vol.voxel_to_world(np.array([[0.0, 0, 0], [3, 4, 5]]))
    np.testing.assert_allclose(corner, [(10, -20, 30), (10 + 5 * 1.25, -20 + 4 * 2.0, 30 + 3 * 0.5)])
    facts = describe(path)
    assert facts["format"] == "mrc" and facts["shape"] == [4, 5, 6] and facts["spacing"] == list(VOXEL[::-1])


def test_axes_stored_in_another_order_are_put_in_z_y_x_order(tmp_path, rng):
    """mapc 3, mapr 1, maps 2: columns run along z, rows along x, sections along y; no origin, so the first voxel is
    at the start indices (nxstart of the columns: z) times the voxel size."""
    stored = rng.normal(size=(4, 5, 6)).astype(np.float32)  # (sections: y, rows: x, columns: z)
    path = _write(tmp_path / "permuted.map", stored, mapc=3, mapr=1, maps=2, mx=5, my=4, mz=6,
                  cella=(5 * 1.25, 4 * 2.0, 6 * 0.5), nxstart=2, nystart=-3, nzstart=7)
    vol = clwave.load(path)
    np.testing.assert_array_equal(vol.data, stored.transpose(2, 0, 1))  # [z, y, x] = stored[y, x, z]
    assert vol.spacing == (0.5, 2.0, 1.25)
    # nxstart (columns) along z, nystart (rows) along x, nzstart (sections) along y
    np.testing.assert_allclose(vol.voxel_to_world(np.zeros((1, 3))), [(-3 * 1.25, 7 * 2.0, 2 * 0.5)])


def test_a_map_is_read_chunk_by_chunk_as_whole(tmp_path, rng):
    stored = rng.normal(size=(9, 10, 11)).astype(np.float32)
    path = _write(tmp_path / "big.mrc", stored, mapc=2, mapr=1, maps=3, mx=10, my=11, mz=9)
    chunked, whole = clwave.load(path, chunks=4), clwave.load(path, chunks=False)
    assert hasattr(chunked.data, "dask") and isinstance(whole.data, np.ndarray)
    np.testing.assert_array_equal(np.asarray(chunked.data), whole.data)
    np.testing.assert_array_equal(whole.data, stored.transpose(0, 2, 1))


def test_a_map_without_a_cell_is_in_voxels_with_a_warning(tmp_path, rng):
    path = _write(tmp_path / "nocell.mrc", rng.normal(size=(3, 4, 5)).astype(np.float32), voxel=(0, 0, 0))
    with pytest.warns(ClwaveWarning, match="no spacing in the file: 1, 1, 1 assumed"):
        vol = clwave.load(path)
    assert vol.spacing == (1.0, 1.0, 1.0) and vol.unit is None


def test_an_image_stack_is_read_as_slices_with_a_warning(tmp_path, rng, capsys):
    stored = rng.normal(size=(7, 5, 6)).astype(np.float32)
    with mrcfile.new(tmp_path / "tilts.st") as mrc:
        mrc.set_data(stored)
        mrc.set_image_stack()
        mrc.voxel_size = (3.0, 3.0, 3.0)
    with pytest.warns(ClwaveWarning, match="is a stack of 7 2-D images .space group 0"):
        vol = clwave.load(tmp_path / "tilts.st")
    np.testing.assert_array_equal(vol.data, stored)
    code, out, err = run(capsys, "info", str(tmp_path / "tilts.st"))
    assert code == 0 and "3, 3, 3 A (x, y, z; --spacing 3,3,3)" in out, out + err


def test_a_compressed_map_keeps_its_unit(tmp_path, capsys):
    stored = np.kron(np.arange(8, dtype=np.float32).reshape(2, 2, 2), np.ones((8, 8, 8), np.float32))
    path = _write(tmp_path / "blocks.mrc", stored)
    code, out, err = run(capsys, "compress", str(path), "--levels", "1", "-o", str(tmp_path / "b.clw"))
    assert code == 0, err
    assert clwave.WaveletVolume.open(tmp_path / "b.clw").unit == "A"


def test_a_map_rendered_with_a_scale_bar_is_labelled_in_its_length(tmp_path):
    """The picture with ``--scale-bar 2`` is the one without it under a bar of 2 Å (20 pixels at 0.1 Å a pixel),
    labelled "0.2 nm" (the label itself: tests/test_scale_bar.py; its font has no Å), not in world "units"."""
    from clwave.cli import main
    from clwave.io.images import draw_scale_bar
    from test_outputs_formats import decode_png

    path = _write(tmp_path / "blocks.mrc", np.kron(np.arange(8, dtype=np.float32).reshape(2, 2, 2),
                                                   np.ones((4, 4, 4), np.float32)))
    view = ["render", str(path), "--levels", "1", "--size", "96x120", "--extent", "12"]
    assert main(view + ["--scale-bar", "2", "-o", str(tmp_path / "a.png")]) == 0
    assert main(view + ["-o", str(tmp_path / "b.png")]) == 0
    (_, barred), (_, plain) = decode_png(tmp_path / "a.png"), decode_png(tmp_path / "b.png")
    np.testing.assert_array_equal(barred, draw_scale_bar(plain, 0.1, "A", 2.0))
    assert not np.array_equal(barred, draw_scale_bar(plain, 0.1, None, 2.0))


def _valid(tmp_path, **fields):
    return _write(tmp_path / "v.mrc", np.zeros((3, 4, 5), np.float32), **fields).read_bytes()


def _with(content, offset, data):
    return content[:offset] + data + content[offset + len(data):]


@pytest.mark.parametrize("case, words", [
    ("cut", r"declares 5 x 4 x 3 voxels \(240 bytes\) but the file holds 100 bytes after its 1,024-byte header"),
    ("huge", r"declares 1073741824 x 4 x 3 voxels .* it is truncated or its header is wrong"),
    ("short", "is not an MRC/CCP4 map clwave reads: Couldn't read enough bytes for MRC header"),
    ("not mrc", "is not an MRC/CCP4 map clwave reads: Map ID string not found"),
    ("complex", r"holds complex float32 samples \(mode 4: a Fourier transform\)"),
    ("mode", "names mode 7, none clwave reads"),
    ("extended", r"declares an extended header of -100 bytes \(nsymbt\); the header is corrupt"),
    ("axes", r"orders the axes mapc, mapr, maps = \(1, 1, 3\), not an order of x, y, z"),
    ("empty", "declares 0 x 4 x 3 columns, rows and sections; each needs at least one"),
    ("stack", r"is a stack of volumes \(space group 401, 3 sections of 1\)")])
def test_a_truncated_or_lying_map_is_refused_in_one_line(tmp_path, capsys, case, words):
    content = _valid(tmp_path)
    content = {"cut": lambda: content[:1124],
               "huge": lambda: _with(content, 0, np.int32(1 << 30).tobytes()),
               "short": lambda: content[:500],
               "not mrc": lambda: _with(content, 208, b"XXXX"),
               "complex": lambda: _with(content, 12, np.int32(4).tobytes()),
               "mode": lambda: _with(content, 12, np.int32(7).tobytes()),
               "extended": lambda: _with(content, 92, np.int32(-100).tobytes()),
               "axes": lambda: _with(content, 68, np.int32(1).tobytes()),
               "empty": lambda: _with(content, 0, np.int32(0).tobytes()),
               "stack": lambda: _with(_with(content, 88, np.int32(401).tobytes()), 36, np.int32(1).tobytes())}[case]()
    (tmp_path / "bad.mrc").write_bytes(content)
    assert_refused_in_one_line(capsys, tmp_path / "bad.mrc", words)


def _smooth(lo, hi):
    """A smooth random field (noise blurred) from ``lo`` to ``hi``, whole numbers."""
    from scipy.ndimage import gaussian_filter

    field = gaussian_filter(np.random.default_rng(3).normal(size=(6, 24, 24)), 3)
    return np.rint(lo + (field - field.min()) / (field.max() - field.min()) * (hi - lo))


def _bytes(tmp_path, name, values):
    """``values`` (0 .. 255 or -128 .. 127) as the bytes of a mode-0 map without IMOD's stamp."""
    return _write(tmp_path / name, np.asarray(values).astype(np.uint8).view(np.int8))


@pytest.mark.parametrize("make", [
    lambda: np.rint(clwave.phantom("hydrogen", 24).data * 255),  # 88 voxels above 127 in its core
    lambda: np.rint(np.random.default_rng(1).normal(128, 20, (6, 16, 16))).clip(0, 255),  # noise about 128
    lambda: _smooth(20, 235)])
def test_unsigned_bytes_without_imods_stamp_are_warned_of_and_read_unsigned_when_said(tmp_path, capsys, make):
    """MRC2014's mode 0 is signed bytes: an unsigned 8-bit map without IMOD's stamp, read so, wraps above 127
    (200 is -56).  Its jumps of more than 128 between neighbours (127 next to -128) say so: a warning naming
    dtype='uint8' (--dtype uint8), which reads it as written, and dtype='int8', which keeps it signed, silently."""
    values = make()
    path = _bytes(tmp_path, "u.mrc", values)
    with pytest.warns(ClwaveWarning, match=r"u.mrc: its bytes \(mode 0\) are read signed, as MRC2014 says, but look "
                                           r"wrapped .* give dtype='uint8' to read them unsigned, dtype='int8'"):
        wrapped = clwave.load(path)
    np.testing.assert_array_equal(wrapped.data, values.astype(np.uint8).view(np.int8))
    with warnings.catch_warnings():
        warnings.simplefilter("error", ClwaveWarning)
        np.testing.assert_array_equal(clwave.load(path, dtype="uint8").data, values)
        np.testing.assert_array_equal(clwave.load(path, dtype=np.int8).data, wrapped.data)
    code, out, err = run(capsys, "compress", str(path), "--levels", "1", "-o", str(tmp_path / "u.clw"))
    assert code == 0 and err.count("look wrapped") == 1 and "give --dtype uint8 to read them unsigned" in err, err
    code, out, err = run(capsys, "compress", str(path), "--levels", "1", "--dtype", "uint8", "-o",
                         str(tmp_path / "u8.clw"))
    assert code == 0 and "wrapped" not in err, err
    assert clwave.WaveletVolume.open(tmp_path / "u8.clw").reconstruct().data.max() > 127


@pytest.mark.parametrize("make", [
    lambda: np.rint(clwave.phantom("hydrogen", 24).data * 254 - 127),  # a density over the whole signed range
    lambda: np.rint(np.random.default_rng(2).normal(0, 20, (6, 16, 16))).clip(-128, 127),  # noise about 0: -1 next to 1
    lambda: _smooth(-120, 120)])
def test_signed_bytes_are_read_signed_without_a_warning(tmp_path, make):
    values = make()
    with warnings.catch_warnings():
        warnings.simplefilter("error", ClwaveWarning)
        np.testing.assert_array_equal(clwave.load(_bytes(tmp_path, "s.mrc", values)).data, values)


@pytest.mark.parametrize("stored, dtype, words", [
    (np.zeros((3, 4, 5), np.float32), "uint8", "dtype= says how an MRC map's bytes .mode 0. are read; .* holds "
                                               "mode 2: leave it out"),
    (np.zeros((3, 4, 5), np.int8), "uint16", "dtype='uint16' of an MRC map of bytes must be 'uint8' .unsigned. or "
                                             "'int8' .signed.")])
def test_a_map_given_another_dtype_is_refused_in_one_line(tmp_path, capsys, stored, dtype, words):
    path = _write(tmp_path / "m.mrc", stored)
    with pytest.raises(clwave.errors.InputError, match=words):
        clwave.load(path, dtype=dtype)
    code, out, err = run(capsys, "info", str(path), "--dtype", dtype)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--dtype" in err, err


def test_info_says_the_centre_and_the_first_voxel_and_the_spacing_as_written(tmp_path, capsys):
    """M3, P5 (trial29): a tomogram at 13.48 Å, origin 0.  Its cell, 464 × 13.48 = 6254.72 Å, is a float32 in the
    header (6254.7202...), over 464 13.4800005: read as the float32's shortest decimal, 13.48 (within 1e-15 of it:
    float64's own rounding of 647.04 / 48).  info names clwave's origin the centre, (n − 1) / 2 voxels from the
    first, and prints the first voxel where ChimeraX and mrcfile place it, the header's origin, 0."""
    path = _write(tmp_path / "tomo.rec", np.zeros((10, 48, 464), np.float32), voxel=13.48)
    assert mrcfile.open(path).voxel_size.x == np.float32(13.4800005)  # the noise, as mrcfile reads it
    vol = clwave.load(path)
    assert vol.spacing == pytest.approx((13.48,) * 3, rel=1e-15, abs=0)
    assert vol.origin == pytest.approx((463 * 13.48 / 2, 47 * 13.48 / 2, 9 * 13.48 / 2), rel=1e-12)
    code, out, err = run(capsys, "info", str(path))
    assert code == 0, err
    assert out.splitlines()[2] == ("spacing    13.48, 13.48, 13.48 A (x, y, z; --spacing 13.48,13.48,13.48), centre "
                                   "3120.62, 316.78, 60.66, corner voxel (least x, y, z) 0, 0, 0")


def _stamped(path):
    """``path`` with IMOD's stamp ("IMOD" at byte 152) written into its header."""
    content = bytearray(path.read_bytes())
    content[152:156] = np.array([1146047817], "<i4").tobytes()
    path.write_bytes(bytes(content))
    return path


def test_an_imod_crop_lies_on_its_parent(tmp_path, rng):
    """M4 (trial29): IMOD's origin is that of the coordinate system relative to the first pixel ("a subvolume should
    have negative origin values", its mrc_format.txt): a crop of voxels from (x 4, y 3, z 2) of a parent at origin 0,
    written as IMOD writes it (its stamp, origin -start * voxel), has its first voxel at +start * voxel, so every voxel
    of it lies where the parent's same voxel lies; the same crop without the stamp (ChimeraX's reading: the origin is
    the first voxel) placed by origin +start * voxel lands there too, and a stamped map of origin 0 at 0."""
    parent = rng.normal(size=(9, 8, 10)).astype(np.float32)
    start = np.array([4, 3, 2])  # x, y, z
    crop = parent[2:7, 3:7, 4:9]
    step = np.array(VOXEL)  # x, y, z
    whole = clwave.load(_stamped(_write(tmp_path / "parent.rec", parent)))
    imod = clwave.load(_stamped(_write(tmp_path / "imod.mrc", crop, origin=tuple(-start * step))))
    chimerax = clwave.load(_write(tmp_path / "chimerax.mrc", crop, origin=tuple(start * step)))

    def position(vol, index):  # world (x, y, z) of voxel index (x, y, z): the centre less half the box
        return np.array(vol.origin) + step * (np.asarray(index) - (np.array(vol.data.shape[::-1]) - 1) / 2)

    np.testing.assert_allclose(position(whole, [0, 0, 0]), [0, 0, 0], atol=1e-12)
    for vol in (imod, chimerax):
        np.testing.assert_array_equal(vol.data, crop)
        for index in ([0, 0, 0], [4, 3, 4], [2, 1, 3]):  # the crop's voxel and the parent's at index + start
            np.testing.assert_allclose(position(vol, index), position(whole, np.add(index, start)), atol=1e-9)
