"""What landed in the twentieth session attacked (attack25): MRC/CCP4 and MGH headers, the scale bar, label maps;
each defect found pinned here, its fix at its one home."""

import tracemalloc

import numpy as np
import pytest

import clwave
from test_mgh import assert_refused_in_one_line
from test_mrc import _valid, _with


def test_an_mrc_extended_header_longer_than_the_file_is_refused_before_it_is_read(tmp_path, capsys):
    """nsymbt 2^31 - 1 in a 1.3 kB file: mrcfile read (allocated) its 2 GiB before finding the file short."""
    path = tmp_path / "bad.mrc"
    path.write_bytes(_with(_valid(tmp_path), 92, np.int32(2 ** 31 - 1).tobytes()))
    tracemalloc.start()
    try:
        with pytest.raises(clwave.errors.FileFormatError):
            clwave.load(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 1 << 24, f"{peak:,} bytes allocated"
    assert_refused_in_one_line(capsys, path, r"declares an extended header of 2,147,483,647 bytes but the file holds "
                                             r"240 bytes after its 1,024-byte header")


def test_a_scale_bar_of_more_pixels_than_a_float_holds_is_refused_in_one_line(tmp_path, capsys):
    """--scale-bar=1e308 at 0.43 units a pixel: 2e308 pixels, infinity, which round() cannot make an int of (an
    internal error, exit 1)."""
    from test_cli import run

    code, out, err = run(capsys, "render", "phantom:hydrogen:16", "--levels", "1", "--size", "64",
                         "--scale-bar=1e308", "-o", str(tmp_path / "a.png"))
    assert code == 2 and "is longer than the 50 pixels the 64-pixel-wide picture has" in err, err
    assert err.count("\n") == 1 and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("shape", [(1, 1), (8, 8), (500, 8)])
def test_a_picture_too_narrow_for_any_bar_says_so(shape):
    """An 8-pixel-wide picture has no room for a bar: the refusal advised a length "from 200 µm to -6e+05 nm"."""
    from clwave.errors import InputError
    from clwave.io.images import draw_scale_bar

    with pytest.raises(InputError, match=rf"the {shape[1]}x{shape[0]}-pixel picture has no room for a scale bar "
                                         r"\(it needs \d+ pixels across\): give a larger picture size, or no scale "
                                         "bar") as caught:
        draw_scale_bar(np.zeros(shape, np.uint8), 0.1, "mm")
    assert "-" not in str(caught.value).replace("-pixel", "")


@pytest.mark.parametrize("unit", [["micrometer"], {"name": "micrometer"}])
def test_an_ome_zarr_unit_that_is_no_name_is_refused_naming_it(tmp_path, unit):
    """A unit of ["micrometer"] was "cannot read ...: TypeError: unhashable type: 'list'; the file may be truncated"."""
    import zarr

    from test_chunked_inputs import _ome

    path, _ = _ome(tmp_path, fmt=3)
    attrs = zarr.open_group(path, mode="r+").attrs
    ome = attrs["ome"]
    ome["multiscales"][0]["axes"][-1]["unit"] = unit
    attrs["ome"] = ome
    with pytest.raises(clwave.errors.FileFormatError, match=r"its OME-Zarr metadata gives the z, y, x axes the units "
                                                            r".*; a unit is a name, e.g. 'micrometer'") as caught:
        clwave.load(path)
    assert "\n" not in str(caught.value) and "TypeError" not in str(caught.value)


@pytest.mark.parametrize("stamp, flags, expected", [(1146047817, 0, np.uint8), (1146047817, 1, np.int8),
                                                    (0, 0, np.int8)], ids=["imod-unsigned", "imod-signed", "mrc2014"])
def test_an_imod_map_of_unsigned_bytes_is_read_unsigned(tmp_path, stamp, flags, expected):
    """Mode 0 is signed bytes in MRC2014, but IMOD marks its files (imodStamp "IMOD" at byte 152) and says in
    imodFlags bit 0 whether their bytes are signed: unset, they are unsigned (all IMOD wrote before 4.2.23), and a
    tomogram's 200 was read as -56, a silently wrong image."""
    from test_mrc import _write

    stored = np.arange(60, dtype=np.uint8).reshape(3, 4, 5) * 4  # 0 .. 236
    path = _write(tmp_path / "t.rec", stored.view(np.int8))
    content = bytearray(path.read_bytes())
    content[152:160] = np.array([stamp, flags], "<i4").tobytes()
    path.write_bytes(bytes(content))
    np.testing.assert_array_equal(clwave.load(path).data, stored.view(expected).astype(np.float32))


@pytest.mark.parametrize("normal", [(1e200, 0, 0), (1e-200, 0, 0), (1e-170, 1e-170, 1e-170)])
def test_a_clip_plane_normal_of_any_non_zero_length_is_a_direction(normal):
    """The normal's length does not matter (coordinates.md §6), but 1e200 (its norm overflowed, with a
    RuntimeWarning) and 1e-200 were refused as "must be a non-zero direction"."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        clip = clwave.Clip(planes=[((0, 0, 0), normal)])
    np.testing.assert_allclose(clip.half_spaces(), [[*np.array(normal) / np.abs(normal).max() /
                                                     np.sqrt(np.count_nonzero(normal)), 0.0]])
    assert clip.contains([(1, 1, 1), (-1, -1, -1)]).tolist() == [True, False]


@pytest.mark.parametrize("kw, volume", [
    (dict(lo=(1e9, 0, 0), hi=(1e9 + 0.5, 1, 1)), ((1e9 - 1, -1, -1), (1e9 + 1, 2, 2))),  # a billion units away
    (dict(lo=(0, 0, 0), hi=(1, 1, 1), planes=[((1e12, 0, 0), (-1, 0, 0))]), ((-1,) * 3, (2,) * 3)),  # a far plane
    (dict(planes=[((1e6, 0, 0), (1, 0, 0)), ((1e6 + 1e-3, 0, 0), (-1, 0, 0))]),
     ((1e6 - 1, -1, -1), (1e6 + 1, 1, 1))),  # a millimetre slab a kilometre away
    (dict(lo=(-1e300, -1e300, -1e300), hi=(1e300, 1e300, 1e300)), ((-1,) * 3, (1,) * 3))])
def test_a_clip_keeps_what_it_keeps_wherever_it_lies(kw, volume):
    """Thinness was measured against the clip's coordinates (1e-9 of them): each of these clips keeps a region (a
    whole unit box, with the far plane), within a ``volume`` box around it too, but was refused as keeping
    nothing."""
    clip = clwave.Clip(**kw)
    assert clip.keeps() and clip.keeps(*map(np.array, volume))


def test_a_clip_box_around_everything_renders_the_whole_volume(tmp_path, capsys):
    """--clip-box of +-1e300 keeps all the volume: it was refused as keeping nothing of it."""
    from test_cli import run

    base = ["render", "phantom:hydrogen:16", "--levels", "1", "--size", "16", "--method", "raytrace", "--xray"]
    code, out, err = run(capsys, *base, "--clip-box=-1e300,-1e300,-1e300,1e300,1e300,1e300",
                         "-o", str(tmp_path / "a.png"), "--raw", str(tmp_path / "a.npy"))
    assert code == 0, err
    assert run(capsys, *base, "-o", str(tmp_path / "b.png"), "--raw", str(tmp_path / "b.npy"))[0] == 0
    np.testing.assert_array_equal(np.load(tmp_path / "a.npy"), np.load(tmp_path / "b.npy"))


@pytest.mark.parametrize("clip", ["--clip-plane=1e300,0,0,-1,0,0", "--clip-box=-1.7e308,-1.7e308,-1.7e308,1.7e308,"
                                                                   "1.7e308,1.7e308"])
def test_a_clip_beyond_float32_keeps_all_without_a_warning(tmp_path, capsys, clip):
    """A plane 1e300 units away (its offset overflowed float32 for the kernel: "RuntimeWarning: overflow encountered
    in cast" printed beside the render) keeps the whole volume: the image is the unclipped one, bit for bit."""
    import warnings

    from test_cli import run

    base = ["render", "phantom:hydrogen:16", "--levels", "1", "--size", "16", "--method", "raytrace", "--xray",
            "--spacing", "0.25,0.25,0.25"]
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        code, out, err = run(capsys, *base, clip, "-o", str(tmp_path / "a.png"), "--raw", str(tmp_path / "a.npy"))
    assert code == 0, err
    assert run(capsys, *base, "-o", str(tmp_path / "b.png"), "--raw", str(tmp_path / "b.npy"))[0] == 0
    np.testing.assert_array_equal(np.load(tmp_path / "a.npy"), np.load(tmp_path / "b.npy"))


@pytest.mark.parametrize("unit", [["um"], {"mm": 1}, np.array("mm")])
def test_a_unit_that_is_no_name_is_an_input_error(tmp_path, unit):
    """unit=["um"] (load's, Volume's, RenderResult.save's) was a TypeError (unhashable type), not the InputError
    naming the world units."""
    from clwave.errors import InputError

    np.save(tmp_path / "v.npy", np.zeros((2, 3, 4), np.float32))
    with pytest.raises(InputError, match=r"must be the world unit, one of m, cm, mm, um, nm, A, or None"):
        clwave.load(tmp_path / "v.npy", unit=unit)
    with pytest.raises(InputError, match=r"must be the world unit"):
        clwave.Volume(np.zeros((2, 3, 4), np.float32), unit=unit)


@pytest.mark.parametrize("tail", ["padding", "members"])
def test_a_gzip_stream_the_trailer_does_not_count_is_read(tmp_path, tail):
    """The gzip trailer counts the last member only: a .mgz with zero padding after it (nibabel reads it) or of two
    members was refused as truncated ("its gzip stream holds 0 bytes")."""
    import gzip

    import nibabel as nib
    from nibabel.freesurfer.mghformat import MGHImage

    data = np.arange(4 * 5 * 6, dtype=np.float32).reshape(4, 5, 6)
    nib.save(MGHImage(data, np.eye(4)), tmp_path / "v.mgz")
    whole = gzip.decompress((tmp_path / "v.mgz").read_bytes())
    content = (tmp_path / "v.mgz").read_bytes() + bytes(16) if tail == "padding" else \
        gzip.compress(whole[:300]) + gzip.compress(whole[300:])
    (tmp_path / "w.mgz").write_bytes(content)
    np.testing.assert_array_equal(clwave.load(tmp_path / "w.mgz").data, data.transpose(2, 1, 0))  # RAS: (k, j, i)


@pytest.mark.parametrize("method, option", [("splat", "clip"), ("splat", "tolerance"), ("raytrace", "omega_s")])
def test_an_option_of_the_other_method_is_an_input_error_naming_it(method, option):
    """progressive(method="splat", clip=...) was Python's TypeError (an unexpected keyword argument 'clip')."""
    from clwave.errors import InputError

    wv = clwave.WaveletVolume.from_volume(clwave.Volume(np.zeros((4, 4, 4), np.float32)), levels=1)
    other = {"splat": "raytrace", "raytrace": "splat"}[method]
    with pytest.raises(InputError, match=rf"{option}= is an option of method='{other}', not of method='{method}'"):
        clwave.progressive(wv, clwave.Camera(size=8), method=method, **{option: None})
