"""FITS cubes (radio and optical spectral-line cubes): written here by astropy, or byte by byte (FITS's 80-character
cards and big-endian samples, independent of astropy); the expected volumes are the arrays written, scaled and turned
by hand (docs/coordinates.md §1: latitude to z, north up; longitude to y, east at -y; the third axis to x)."""

import gzip
import json
import warnings

import numpy as np
import pytest
from astropy.io import fits

import clwave
from clwave.errors import ClwaveWarning, FileFormatError, InputError
from clwave.io.loaders import describe
from test_cli import run
from test_mgh import assert_refused_in_one_line

SKY = dict(CTYPE1="RA---SIN", CTYPE2="DEC--SIN", CTYPE3="VRAD", CUNIT1="deg", CUNIT2="deg", CUNIT3="m/s",
           CDELT1=-0.001, CDELT2=0.001, CDELT3=5000.0, CRVAL1=150.0, CRVAL2=2.0, CRVAL3=0.0,
           CRPIX1=4.0, CRPIX2=3.0, CRPIX3=1.0, BUNIT="Jy/beam")


def _card(key, value=None):
    """One 80-character header card: ``key`` alone (END, COMMENT), or ``key = value`` in FITS's fixed format."""
    if value is None:
        return f"{key:<80}"
    if isinstance(value, str):
        return f"{key:<8}= '{value:<8}'".ljust(80)
    text = ("T" if value else "F") if isinstance(value, bool) else repr(value)
    return f"{key:<8}= {text:>20}".ljust(80)


def fits_bytes(samples, bitpix, cards=(), naxes=None):
    """A FITS file's bytes written by hand: its primary header (``naxes``: NAXIS1 first, default the ``samples``'
    shape reversed) and ``samples`` big-endian, each padded to 2880."""
    naxes = list(samples.shape[::-1]) if naxes is None else naxes
    head = [_card("SIMPLE", True), _card("BITPIX", bitpix), _card("NAXIS", len(naxes))]
    head += [_card(f"NAXIS{n}", length) for n, length in enumerate(naxes, 1)]
    head += [_card(k, v) for k, v in dict(cards).items()] + [_card("END")]
    header = "".join(head).encode("ascii")
    header += b" " * (-len(header) % 2880)
    body = samples.astype(samples.dtype.newbyteorder(">")).tobytes()
    return header + body + b"\0" * (-len(body) % 2880)


def write(path, samples, bitpix, cards=(), **kw):
    path.write_bytes(fits_bytes(samples, bitpix, cards, **kw))
    return path


def as_seen(stored_spec_dec_ra):
    """The volume of a (spectral, Dec, RA) cube whose RA decreases and Dec increases along its pixels, by hand:
    (z, y, x) = (Dec, RA, spectral), unflipped."""
    return np.transpose(stored_spec_dec_ra, (1, 2, 0))


@pytest.mark.parametrize("writer", ["by hand", "astropy"])
def test_scaled_int16_with_blank_is_read_as_its_values(tmp_path, capsys, rng, writer):
    """BSCALE and BZERO applied, BLANK is no data: refused (NaN) until nan= gives it a value."""
    stored = rng.integers(-3000, 3000, (4, 5, 6)).astype(np.int16)
    stored[1, 2, 3] = -32768
    scaling = dict(BSCALE=0.5, BZERO=100.0, BLANK=-32768)
    path = tmp_path / "scaled.fits"
    if writer == "astropy":  # the integers written as they are, the keywords set after (as a survey's pipeline does)
        hdu = fits.PrimaryHDU(stored, fits.Header(SKY))
        hdu.header.update(scaling)
        hdu.writeto(path)
    else:
        write(path, stored, 16, SKY | scaling)
    with pytest.raises(InputError, match="non-finite voxel"):
        clwave.load(path)
    code, _, err = run(capsys, "info", str(path))
    assert code == 0, err
    code, _, err = run(capsys, "compress", str(path), "-o", str(tmp_path / "s.clw"))
    assert code == 2 and "give NaN voxels a value with --nan VALUE" in err and len(err.strip().splitlines()) == 1
    vol = clwave.load(path, nan=-1.0)
    expected = stored * 0.5 + 100.0
    expected[1, 2, 3] = -1.0
    np.testing.assert_array_equal(vol.data, as_seen(expected).astype(np.float32))
    assert vol.spacing == (1.0, 1.0, 1.0) and vol.unit is None and vol.origin == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("bitpix", [8, 16, 32, 64, -32, -64])
@pytest.mark.parametrize("cards", [{}, dict(BSCALE=2.0), dict(BZERO=1.0), dict(BLANK=3), dict(BZERO=32768.0),
                                   dict(BSCALE=1.0, BZERO=2147483648.0), dict(BZERO=9223372036854775808.0)])
def test_the_sample_type_weighed_is_the_one_astropy_reads(tmp_path, bitpix, cards):
    """What is weighed before a cube is read (and what ``clwave info`` says) is the type of what astropy reads."""
    from clwave.io.loaders.fits import samples

    dtype = {8: np.uint8, 16: np.int16, 32: np.int32, 64: np.int64, -32: np.float32, -64: np.float64}[bitpix]
    path = write(tmp_path / "t.fits", np.ones((2, 2, 2), dtype), bitpix, cards)
    if bitpix in (8, 16) and cards.get("BZERO") == 2.0 ** 63:  # read as float32: every pixel 2^63 (loose30)
        with pytest.raises(FileFormatError, match=r"BZERO = 9\.223372036854776e\+18, which map every .* to "
                                                  r"9\.22337e\+18 in float32"):
            clwave.load(path)
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", fits.verify.VerifyWarning)  # a float cube's BLANK: ignored
        with fits.open(path) as hdul:
            read = hdul[0].data.dtype.newbyteorder("=")
            assert samples(hdul[0].header) == read
    assert clwave.load(path).stored_dtype == read


@pytest.mark.parametrize("dtype, bitpix, cards", [
    (">f4", -32, {}), (">f8", -64, {}), (">i4", 32, {}), (">u1", 8, {}),
    (">i2", 16, dict(BZERO=32768.0, BSCALE=1.0))])  # astropy's unsigned 16-bit: stored - 32768, BZERO 32768
def test_big_endian_samples_are_read_exactly(tmp_path, rng, dtype, bitpix, cards):
    values = rng.integers(0, 200 if bitpix == 8 else 60000, (3, 4, 5))
    stored = (values - 32768 if cards else values).astype(dtype)
    path = write(tmp_path / "v.fits", stored, bitpix, SKY | cards)
    np.testing.assert_array_equal(clwave.load(path).data, as_seen(values).astype(np.float32))


def test_nan_is_no_data_as_in_other_formats(tmp_path, rng, capsys):
    cube = rng.normal(size=(4, 5, 6)).astype(np.float32)
    cube[0, 0, :] = np.nan
    fits.PrimaryHDU(cube, fits.Header(SKY)).writeto(tmp_path / "nan.fits")
    code, _, err = run(capsys, "render", str(tmp_path / "nan.fits"), "-o", str(tmp_path / "n.png"))
    assert code == 2 and "--nan VALUE" in err
    vol = clwave.load(tmp_path / "nan.fits", nan=0.0)
    np.testing.assert_array_equal(vol.data, as_seen(np.nan_to_num(cube, nan=0.0)))


@pytest.mark.parametrize("layout", ["stokes last", "stokes third"])
def test_a_degenerate_stokes_axis_is_dropped(tmp_path, rng, layout):
    cube = rng.normal(size=(4, 5, 6)).astype(np.float32)
    if layout == "stokes last":  # RA, Dec, VRAD, STOKES of 1
        stored, cards = cube[None], SKY | dict(CTYPE4="STOKES", CDELT4=1.0, CRVAL4=1.0, CRPIX4=1.0)
    else:  # RA, Dec, STOKES of 1, VRAD
        stored = cube[:, None]
        cards = SKY | dict(CTYPE3="STOKES", CUNIT3="", CDELT3=1.0, CRVAL3=1.0, CTYPE4="VRAD", CUNIT4="m/s",
                           CDELT4=5000.0, CRVAL4=0.0, CRPIX4=1.0)
    path = write(tmp_path / "s.fits", stored, -32, cards)
    np.testing.assert_array_equal(clwave.load(path).data, as_seen(cube))
    np.testing.assert_array_equal(np.asarray(clwave.load(path, chunks=3).data), as_seen(cube))
    assert describe(path)["shape"] == [5, 6, 4]


def test_several_stokes_planes_without_frame_are_refused_in_one_line(tmp_path, capsys):
    """Read without frame= (tests/test_frames.py reads one); planes along two axes are refused even with it."""
    path = write(tmp_path / "iquv.fits", np.zeros((4, 3, 5, 6), np.float32), -32,
                 SKY | dict(CTYPE4="STOKES", CDELT4=1.0, CRVAL4=1.0, CRPIX4=1.0))
    with pytest.raises(FileFormatError, match=r"holds 4 planes along its axis 4 \(STOKES\) beside its cube; clwave "
                                              r"reads one volume: pick one, frame=K for K in 0 .. 3 \(or -4 .. -1"):
        clwave.load(path)
    path = write(tmp_path / "two.fits", np.zeros((2, 4, 3, 5, 6), np.float32), -32,
                 SKY | dict(CTYPE4="STOKES", CTYPE5="TIME"))
    with pytest.raises(FileFormatError, match=r"holds planes along its axes 4 \(4\) and 5 \(2\) beside its cube; "
                                              "clwave reads one cube, picking a plane along one axis only"):
        clwave.load(path, frame=0)
    assert_refused_in_one_line(capsys, path, "picking a plane along one axis only")


@pytest.mark.parametrize("name", ["c.fits.gz", "c.fit", "c.fts", "c.fits.fz", "c.FITS"])
def test_every_name_and_compression_reads_the_same_cube(tmp_path, rng, name):
    cube = rng.integers(-100, 100, (4, 5, 6)).astype(np.int16)
    header = fits.Header(SKY)
    if name.endswith(".fz"):  # a tile-compressed image: an empty primary HDU, the image in a binary table
        fits.HDUList([fits.PrimaryHDU(), fits.CompImageHDU(cube, header)]).writeto(tmp_path / name)
    elif name.endswith(".gz"):
        (tmp_path / name).write_bytes(gzip.compress(fits_bytes(cube, 16, SKY)))
    else:
        write(tmp_path / name, cube, 16, SKY)
    vol = clwave.load(tmp_path / name)
    np.testing.assert_array_equal(vol.data, as_seen(cube).astype(np.float32))
    assert describe(tmp_path / name)["shape"] == [5, 6, 4]


def test_a_cube_in_an_extension_is_found_and_read_chunk_by_chunk(tmp_path, rng):
    """An image extension (a JWST cube's SCI) after an empty primary HDU and a 2-D image; read whole and in chunks."""
    cube = rng.normal(size=(7, 9, 11)).astype(np.float32)
    fits.HDUList([fits.PrimaryHDU(), fits.ImageHDU(np.ones((3, 4), np.float32), name="WHITE"),
                  fits.ImageHDU(cube, fits.Header(SKY), name="SCI")]).writeto(tmp_path / "ifu.fits")
    whole, chunked = clwave.load(tmp_path / "ifu.fits", chunks=False), clwave.load(tmp_path / "ifu.fits", chunks=4)
    assert hasattr(chunked.data, "dask")
    np.testing.assert_array_equal(whole.data, as_seen(cube))
    np.testing.assert_array_equal(np.asarray(chunked.data), as_seen(cube))
    assert describe(tmp_path / "ifu.fits")["fits"]["hdu"] == 2


def _north_east(path, layout):
    """A cube of 4 channels, 6 Dec and 8 RA pixels, bright at its north-east corner (the highest RA and Dec) in every
    channel, written with its axes in ``layout``'s order and directions."""
    cube = np.full((4, 6, 8), 0.1, np.float32)  # (spectral, Dec, RA), RA decreasing: east at RA pixel 0
    cube[:, 4:, :2] = 1.0  # the faint rest makes the whole cube the content the camera frames
    cards = dict(SKY)
    if layout == "RA increasing":  # east at the last RA pixel
        cube, cards["CDELT1"] = cube[:, :, ::-1], 0.001
    elif layout == "Dec decreasing":  # north at the first Dec pixel
        cube, cards["CDELT2"] = cube[:, ::-1], -0.001
    elif layout == "spectral first":  # NAXIS1 VRAD, NAXIS2 RA, NAXIS3 Dec: numpy (Dec, RA, spectral)
        cube = cube.transpose(1, 2, 0)
        for n, m in ((1, 3), (2, 1), (3, 2)):
            for key in ("CTYPE", "CUNIT", "CDELT", "CRVAL", "CRPIX"):
                cards[f"{key}{n}"] = SKY[f"{key}{m}"]
    return write(path, cube, -32, cards)


@pytest.mark.parametrize("layout", ["usual", "RA increasing", "Dec decreasing", "spectral first"])
def test_the_sky_is_seen_north_up_east_left(tmp_path, capsys, layout):
    """Emission at the north-east corner lies at the volume's +z (north) and -y (east) edges, and a render from +x
    (azimuth 0, elevation 0: u = +y right, v = +z up) shows it top left, as a sky chart does; the default view (30,
    20) keeps it on the left and at the top."""
    path = _north_east(tmp_path / "ne.fits", layout)
    vol = clwave.load(path)
    expected = np.full((6, 8, 4), 0.1, np.float32)  # (Dec: z, RA: y, spectral: x)
    expected[4:, :2, :] = 1.0
    np.testing.assert_array_equal(vol.data, expected)
    for view in (("--azimuth", "0", "--elevation", "0"), ()):
        raw = tmp_path / "r.npy"
        code, _, err = run(capsys, "render", str(path), *view, "--fit", "box", "--size", "24", "--levels",
                           "1", "-o", str(tmp_path / "r.png"), "--raw", str(raw), "--force")
        assert code == 0, err
        image = np.load(raw)[..., 0]
        quarters = {(top, left): image[12 * (1 - top):12 * (2 - top), 12 * (1 - left):12 * (2 - left)].sum()
                    for top in (True, False) for left in (True, False)}  # row 0 at the top
        assert max(quarters, key=quarters.get) == (True, True), (view, quarters)


def test_info_names_the_axes_and_what_they_become(tmp_path, capsys):
    path = _north_east(tmp_path / "ne.fits", "RA increasing")
    code, out, err = run(capsys, "info", str(path))
    assert code == 0, err
    assert "volume     4 x 8 x 6 voxels (x, y, z)" in out
    assert "cube       HDU 0 (PRIMARY), values in Jy/beam; NaN (and BLANK) are no data" in out
    assert ("axes       1 RA---SIN (8, 0.001 deg a pixel) -> y reversed; 2 DEC--SIN (6, 0.001 deg a pixel) -> z; "
            "3 VRAD (4, 5000 m/s a pixel) -> x; in pixels, north up and east left seen from +x (docs/coordinates.md "
            "§1); --spacing 1,1,2 makes the spectral axis as deep as the sky is wide") in out
    code, out, err = run(capsys, "info", str(path), "--json")
    facts = json.loads(out)
    assert facts["format"] == "fits" and facts["shape"] == [6, 8, 4] and facts["unit"] is None
    assert [a["axis"] for a in facts["fits"]["axes"]] == ["y", "z", "x"]
    code, _, err = run(capsys, "info", str(path), "--orientation", "LPS")
    assert code == 2 and "a fits input is put on the sky, north up and east left, by its own header" in err


def test_compress_and_render_a_cube_through_the_command_line(tmp_path, capsys, rng):
    cube = np.zeros((8, 12, 16), np.float32)
    cube[2:6, 4:8, 5:11] = rng.random((4, 4, 6)).astype(np.float32)
    fits.PrimaryHDU(cube, fits.Header(SKY)).writeto(tmp_path / "hi.fits")
    code, _, err = run(capsys, "compress", str(tmp_path / "hi.fits"), "--levels", "1", "--spacing", "1,1,0.5", "-o",
                       str(tmp_path / "hi.clw"))
    assert code == 0, err
    model = clwave.WaveletVolume.open(tmp_path / "hi.clw")
    assert model.shape == (12, 16, 8) and model.spacing == (1.0, 1.0, 0.5)  # the spectral axis (x) halved
    code, _, err = run(capsys, "render", str(tmp_path / "hi.clw"), "--size", "16", "-o", str(tmp_path / "hi.png"))
    assert code == 0, err


def test_oblong_sky_pixels_keep_their_aspect(tmp_path, rng, capsys):
    """Dec pixels twice the RA pixels' size: z spaced 2, the rest 1 (pixels); info names it as the file's, and the
    --spacing it prints keeps that aspect and makes the 3 channels as deep as the 4 Dec pixels of 2 are tall (8)."""
    cube = rng.normal(size=(3, 4, 5)).astype(np.float32)
    path = write(tmp_path / "o.fits", cube, -32, SKY | dict(CDELT2=0.002))
    assert clwave.load(path).spacing == (2.0, 1.0, 1.0)
    assert describe(path)["spacing"] == [2.0, 1.0, 1.0]
    code, out, err = run(capsys, "info", str(path))
    assert code == 0, err
    assert "--spacing 2,1,2.6666667 makes the spectral axis as deep as the sky is wide" in out
    vol = clwave.load(path, spacing=(2.0, 1.0, 2.6666667))
    assert vol.data.shape[2] * vol.spacing[2] == pytest.approx(vol.data.shape[0] * vol.spacing[0], rel=1e-6)


def test_a_grid_turned_on_the_sky_goes_by_its_nearest_axes_with_a_warning(tmp_path, rng):
    """PC matrix of a 20 degree turn (CROTA2 20): north is nearest pixel axis 2, as without the turn."""
    cube = rng.normal(size=(3, 4, 5)).astype(np.float32)
    c, s = float(np.cos(np.radians(20))), float(np.sin(np.radians(20)))
    path = write(tmp_path / "t.fits", cube, -32, SKY | dict(PC1_1=c, PC1_2=-s, PC2_1=s, PC2_2=c))
    with pytest.warns(ClwaveWarning, match="its sky is turned 20.00 degrees on its pixel grid"):
        vol = clwave.load(path)
    np.testing.assert_array_equal(vol.data, as_seen(cube))


def test_an_unreadable_wcs_is_the_pixel_grid_with_a_warning(tmp_path, rng):
    cube = rng.normal(size=(3, 4, 5)).astype(np.float32)
    path = write(tmp_path / "w.fits", cube, -32, SKY | dict(CTYPE1="RA---XXX"))
    with pytest.warns(ClwaveWarning, match="its WCS is not read"):
        vol = clwave.load(path)
    np.testing.assert_array_equal(vol.data, as_seen(cube))  # axis 2 up, 1 to the right: as a usual cube


def _good(tmp_path):
    return fits_bytes(np.zeros((3, 4, 5), np.int16), 16, SKY)


def _edit(content, key, value=None, card=None):
    """``content`` with the card of ``key`` given another ``value``, or replaced by another ``card``."""
    at = content.index(f"{key:<8}=".encode())
    return content[:at] + (card or _card(key, value)).ljust(80).encode() + content[at + 80:]


@pytest.mark.parametrize("case, words", [
    ("huge", r"declares 1099511627776 x 4 x 3 voxels .* but the file holds 2,880 bytes after its 2,880-byte header"),
    ("negative", r"declares 5 x -4 x 3 pixels \(NAXISn\); a length cannot be negative"),
    ("zero", r"its HDU 0 declares 5 x 4 x 0 pixels; each axis needs at least one"),
    ("bitpix", r"has BITPIX = 12, none FITS has"),
    ("naxis", r"has NAXIS = 1000, FITS allows 0 to 999"),
    ("text", r"has NAXIS2 = 'four', not an integer"),
    ("float", r"has BITPIX = 16.0, none FITS has"),
    ("missing", r"its HDU 0 has no NAXIS3; the header is corrupt"),
    ("groups", r"has GCOUNT = 1, PCOUNT = -5760; a count cannot be negative"),
    ("scale", r"has BSCALE = 'abc', not a finite number; the header is corrupt"),
    ("offset", r"has BZERO = True, not a finite number; the header is corrupt"),
    ("cut", r"declares 5 x 4 x 3 voxels \(120 bytes\) but the file holds 100 bytes"),
    ("not fits", r"is not a FITS file \(it does not begin with SIMPLE = T\)"),
    ("image", r"holds no image of 3 or more axes \(its HDUs: 0: a 2-D image\); clwave reads data cubes"),
    ("gzip name", r"is not gzip-compressed, but its name ends in .gz: name it bad.fits$"),
    ("gzipped", r"is gzip-compressed: name it bad.fits.gz$")])
def test_a_lying_or_truncated_header_is_refused_in_one_line(tmp_path, capsys, case, words):
    content = _good(tmp_path)
    content = {"huge": lambda: _edit(content, "NAXIS1", 1 << 40),
               "negative": lambda: _edit(content, "NAXIS2", -4),
               "zero": lambda: _edit(content, "NAXIS3", 0),
               "bitpix": lambda: _edit(content, "BITPIX", 12),
               "naxis": lambda: _edit(content, "NAXIS", 1000),
               "text": lambda: _edit(content, "NAXIS2", "four"),
               "float": lambda: _edit(content, "BITPIX", 16.0),
               "missing": lambda: _edit(content, "NAXIS3", card="COMMENT"),
               "groups": lambda: _edit(content, "CRPIX3", card=_card("PCOUNT", -5760)),
               "scale": lambda: _edit(content, "CRPIX3", card=_card("BSCALE", "abc")),
               "offset": lambda: _edit(content, "CRPIX3", card=_card("BZERO", True)),
               "cut": lambda: content[:2880 + 100],
               "not fits": lambda: b"\x89PNG" + content[4:],
               "image": lambda: fits_bytes(np.zeros((4, 5), np.int16), 16),
               "gzip name": lambda: content,
               "gzipped": lambda: gzip.compress(content)}[case]()
    name = "bad.fits.gz" if case == "gzip name" else "bad.fits"
    (tmp_path / name).write_bytes(content)
    assert_refused_in_one_line(capsys, tmp_path / name, words)


def test_a_gzip_bomb_is_weighed_before_it_is_read(tmp_path, capsys):
    """A 4 kB .fits.gz declaring a 4096^3 float32 cube (256 GiB): its gzip trailer made to agree with the header (modulo
    2^32), so only the weighing of the cube before reading refuses it, in one line."""
    declared = 2880 + 4 * 4096 ** 3
    stream = bytearray(gzip.compress(fits_bytes(np.zeros((1, 1, 1), np.float32), -32, naxes=[4096] * 3)))
    stream[-4:] = (declared % 2 ** 32).to_bytes(4, "little")
    (tmp_path / "bomb.fits.gz").write_bytes(bytes(stream))
    with pytest.raises(MemoryError, match=r"4096 x 4096 x 4096"):
        clwave.load(tmp_path / "bomb.fits.gz")
    code, out, err = run(capsys, "compress", str(tmp_path / "bomb.fits.gz"), "-o", str(tmp_path / "b.clw"))
    assert code == 2 and len(err.strip().splitlines()) == 1 and not (tmp_path / "b.clw").exists(), err
    facts = describe(tmp_path / "bomb.fits.gz")  # what the header declares, nothing read
    assert facts["shape"] == [4096] * 3 and facts["stored_shape"] == [4096] * 3


def test_chunks_are_refused_for_a_compressed_cube(tmp_path):
    (tmp_path / "c.fits.gz").write_bytes(gzip.compress(fits_bytes(np.zeros((3, 4, 5), np.float32), -32)))
    with pytest.raises(InputError, match=r"not to a compressed FITS file \(gunzip a .fits.gz, funpack a .fz first\)"):
        clwave.load(tmp_path / "c.fits.gz", chunks=2)


def test_a_cube_without_a_wcs_keeps_its_pixel_grid(tmp_path, rng):
    """No CTYPE: axis 1 to the right (+y), 2 up (+z), 3 along x, as ds9 shows a plane (pixel 1, 1 bottom left)."""
    cube = rng.normal(size=(3, 4, 5)).astype(np.float32)
    np.testing.assert_array_equal(clwave.load(write(tmp_path / "p.fits", cube, -32)).data, as_seen(cube))
