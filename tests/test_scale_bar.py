"""Scale bars burnt into pictures (docs/coordinates.md §3): the bar's length in pixels measured on the PNG read back
by the decoder of tests/test_outputs_formats.py (and Pillow), against LENGTH / pixel; the nice length and the label
against hand-written cases; position, contrast, 16 bits, transparency, the refusals and the command line."""

import json

import numpy as np
import pytest
from PIL import Image

from clwave.cli import main
from clwave.errors import InputError
from clwave.io.images import draw_scale_bar, length_label, nice_length
from clwave.io.result import RenderResult
from clwave.model.camera import Camera
from clwave.model.conebeam import ConeBeam
import test_outputs_formats
from test_outputs_formats import decode_png

nifti = test_outputs_formats.nifti  # the fixture: a NIfTI of 0.5 mm voxels
SPLAT = ["render", "phantom:hydrogen:16", "--levels", "1"]


def flat(value, shape=(200, 300), pixel=0.25, mode="xray", perspective=False) -> RenderResult:
    """An orthographic render's result of one value everywhere, ``pixel`` world units a pixel."""
    camera = Camera(30, 20, shape, extent=pixel * shape[1], perspective=perspective)
    channels = 1 if mode == "xray" else 4
    return RenderResult(np.full((*shape, channels), value, np.float32),
                        dict(mode=mode, camera=camera.to_dict(), pixel=pixel))


def bar_rows(picture, top):
    """The rows of the longest horizontal run of ``top`` (the bar: the label's strokes are shorter), and the run's
    first and last columns, measured on the picture alone."""
    best, found = 0, []
    for r, row in enumerate(picture == top):
        edges = np.flatnonzero(np.diff(np.concatenate([[0], row.astype(np.int8), [0]])))
        for start, stop in zip(edges[::2], edges[1::2]):
            if stop - start > best:
                best, found = stop - start, [(r, start, stop - 1)]
            elif stop - start == best:
                found.append((r, start, stop - 1))
    return best, found


@pytest.mark.parametrize("width, want", [(100.0, 20.0), (37.0, 5.0), (0.9, 0.1), (50.0, 10.0), (4.99, 0.5),
                                         (1.0, 0.2), (12e-6, 2e-6), (6e-3, 1e-3), (2.4e4, 2e3)])
def test_the_nice_length_is_the_longest_1_2_5_within_a_fifth(width, want):
    assert nice_length(width) == pytest.approx(want, rel=1e-12)


@pytest.mark.parametrize("length, unit, text", [
    (500, "um", "500 µm"), (0.5, "mm", "500 µm"), (1000, "um", "1 mm"), (10, "mm", "10 mm"), (2000, "mm", "2 m"),
    (5, "cm", "5 cm"), (0.2, "cm", "2 mm"), (0.0005, "um", "0.5 nm"), (0.002, "mm", "2 µm"), (5, None, "5 units"),
    (1, None, "1 unit"), (0.25, None, "0.25 units"), (2500, "m", "2500 m"),
    (50, "A", "5 nm"), (2000, "A", "200 nm"), (5, "nm", "5 nm"),  # an MRC map's ångströms, an OME-Zarr's nanometres
])
def test_the_label_in_the_unit_that_reads_1_to_999(length, unit, text):
    assert length_label(length, unit) == text


@pytest.mark.parametrize("length, pixel", [(10.0, 0.25), (7.3, 0.25), (3.0, 0.07), (1e-3, 1.3e-5), (20.0, 0.5)])
def test_the_bar_is_length_over_pixel_within_one_pixel(tmp_path, length, pixel):
    """On a mid-grey picture: the white run's length is LENGTH / pixel within one pixel, black at both its ends and
    below it (the outline), at the bottom right."""
    path = tmp_path / "a.png"
    flat(0.5, pixel=pixel).save(path, window=(0, 1), scale_bar=length, unit="mm")
    _, picture = decode_png(path)
    run, rows = bar_rows(picture, 255)
    assert abs(run - length / pixel) <= 1, (run, length / pixel)
    (r, first, last), (bottom, _, _) = rows[0], rows[-1]
    assert [rr for rr, _, _ in rows] == list(range(r, bottom + 1)) and bottom - r + 1 >= 2  # one bar, 2 px thick
    assert picture[r, first - 1] == picture[r, last + 1] == picture[bottom + 1, first] == 0
    assert 300 - 20 < last < 300 and 200 - 20 < bottom < 200  # the bottom-right corner, within a margin
    changed = np.argwhere(picture != 128)
    assert changed[:, 0].min() > 100 and changed[:, 1].min() > 150  # bar and label in the bottom-right quadrant
    assert np.count_nonzero(picture[:r, first:last + 1] > 200) > 10  # the label above the bar
    with Image.open(path) as im:  # and Pillow reads the same
        np.testing.assert_array_equal(np.asarray(im), picture)


@pytest.mark.parametrize("value", [0.0, 1.0])
def test_the_bar_reads_on_black_and_on_white(value):
    """On black the bar and label are white (at least the bar's length of them in a row); on white their outline is
    black: the bar's length plus its outline in the row below it."""
    result = flat(value)
    picture = result.picture(window=(0, 1), scale_bar=10.0, unit="mm")
    assert np.all(picture[:150, :] == round(255 * value))  # nothing drawn above the corner
    ink = 0 if value else 255
    longest = max(np.max(np.convolve((row == ink).astype(int), np.ones(40, int), "valid")) for row in picture)
    assert longest == 40  # a run of the bar's 40 pixels in the ink that contrasts
    assert np.count_nonzero(np.abs(picture.astype(int) - ink) < 60) > 100  # and the label's strokes


def test_16_bits_grey_the_same_bar_at_full_scale(tmp_path):
    path8, path16 = tmp_path / "a8.png", tmp_path / "a16.png"
    flat(0.5).save(path8, window=(0, 1), scale_bar=10.0, unit="um")
    flat(0.5).save(path16, window=(0, 1), scale_bar=10.0, unit="um", bit_depth=16)
    (_, eight), (_, sixteen) = decode_png(path8), decode_png(path16)
    assert sixteen.dtype == np.dtype(">u2")
    np.testing.assert_array_equal(sixteen == 65535, eight == 255)
    np.testing.assert_array_equal(sixteen == 0, eight == 0)
    assert bar_rows(sixteen, 65535)[0] == 40


@pytest.mark.parametrize("bits", [8, 16])
def test_a_transparent_picture_gets_an_opaque_bar(tmp_path, bits):
    """A shaded image of nothing, transparent: the bar and label opaque (white, black outline), the rest untouched."""
    path = tmp_path / "a.png"
    flat(0.0, mode="emission-absorption").save(path, background="transparent", bit_depth=bits, scale_bar=10.0,
                                               unit="mm")
    _, rgba = decode_png(path)
    top = (1 << bits) - 1
    assert rgba.shape == (200, 300, 4)
    alpha, colour = rgba[..., 3], rgba[..., :3]
    assert np.all(colour[alpha == 0] == 0) and np.count_nonzero(alpha) > 100
    assert bar_rows(np.where(alpha == top, colour[..., 0], 0), top)[0] == 40  # the bar, opaque and white
    assert np.any((alpha == top) & (colour[..., 0] == 0))  # its outline, opaque and black
    assert np.all(colour[..., 0] == colour[..., 2])  # white and black: no tint
    if bits == 8:
        with Image.open(path) as im:
            assert im.mode == "RGBA"
            np.testing.assert_array_equal(np.asarray(im), rgba)


def test_an_rgb_picture_over_a_background():
    picture = flat(0.0, mode="emission-absorption").picture(background=(0.0, 0.0, 1.0), scale_bar=True, unit="mm")
    assert picture.shape == (200, 300, 3) and tuple(picture[0, 0]) == (0, 0, 255)
    run, _ = bar_rows(picture[..., 0], 255)
    assert run == 40 and nice_length(300 * 0.25) == 10.0  # the default: 10 mm of a 75 mm wide picture


@pytest.mark.parametrize("meta, words", [
    (dict(camera=Camera(30, 20, (64, 64), perspective=True).to_dict(), pixel=0.1), "needs an orthographic view"),
    (dict(camera=ConeBeam(500, 1000, (64, 64), 0.2).to_dict(), pixel=0.1), "needs an orthographic view"),
    (dict(pixel=0.1), "needs an orthographic view"),
])
def test_a_view_without_one_scale_is_refused(meta, words):
    with pytest.raises(InputError, match=words):
        RenderResult(np.zeros((64, 64, 1), np.float32), meta).picture(scale_bar=True)


@pytest.mark.parametrize("scale_bar, words", [
    (200.0, "is longer than the"), (0.3, "is under 2 pixels"), (0, "must be True"), (-1, "must be True"),
    (float("nan"), "must be True"), ("10", "must be True"),
])
def test_a_bar_that_does_not_fit_or_is_no_length_is_refused(tmp_path, scale_bar, words):
    path = tmp_path / "a.png"
    with pytest.raises(InputError, match=words):
        flat(0.5).save(path, scale_bar=scale_bar, unit="mm")
    assert not path.exists()


def test_a_default_bar_that_does_not_fit_asks_for_a_larger_picture():
    """The default length (a fifth of the width) in a 16-pixel picture at 1.73 units a pixel: 2.89 pixels where the
    margins leave 2.  The fix is a larger picture; "or no length" was offered, though no length was what was given."""
    with pytest.raises(InputError, match=r"is longer than the 2 pixels .*: give a larger picture size, or no scale "
                                         r"bar$") as caught:
        flat(0.5, shape=(16, 16), pixel=1.73).picture(scale_bar=True)
    assert "no length" not in str(caught.value)


def test_a_label_that_does_not_fit_and_a_file_of_values_are_refused(tmp_path):
    with pytest.raises(InputError, match="its label .* does not fit the 20x20 picture"):
        flat(0.5, shape=(20, 20)).picture(scale_bar=True)
    for name in ("a.tif", "a.npy"):
        with pytest.raises(InputError, match="scale_bar= sets a .png's picture"):
            flat(0.5).save(tmp_path / name, scale_bar=True)
    assert list(tmp_path.iterdir()) == []


def test_the_command_line_burns_in_the_bar_where_it_writes_pictures(tmp_path, capsys):
    """``render --scale-bar 6 --extent 48 --size 96``: 12 pixels; the --raw values and --stats unchanged by it;
    ``--scale-bar`` alone the nice length, 5 of a 48-unit-wide view; a turntable GIF's frames and progressive PNG
    frames carry it too."""
    png, raw = tmp_path / "a.png", tmp_path / "a.npy"
    view = ["--extent", "48", "--size", "80x96"]
    assert main(SPLAT + view + ["--scale-bar", "6", "-o", str(png), "--raw", str(raw)]) == 0
    _, picture = decode_png(png)
    assert bar_rows(picture, 255)[0] == 12
    assert main(SPLAT + view + ["-o", str(tmp_path / "b.png"), "--raw", str(tmp_path / "b.npy")]) == 0
    np.testing.assert_array_equal(np.load(raw), np.load(tmp_path / "b.npy"))
    assert main(SPLAT + view + ["--scale-bar", "-o", str(tmp_path / "c.png"), "--stats", str(tmp_path / "c.json")]) == 0
    assert json.loads((tmp_path / "c.json").read_text())["pixel"] == 0.5
    assert bar_rows(decode_png(tmp_path / "c.png")[1], 255)[0] == 10  # 5 units: 48 / 5 is 9.6, 5 the nice length
    gif = tmp_path / "t.gif"
    assert main(SPLAT + view + ["--scale-bar", "6", "--turntable", "2", "-o", str(gif)]) == 0
    with Image.open(gif) as im:
        for k in range(2):
            im.seek(k)
            assert bar_rows(np.asarray(im.convert("L")), 255)[0] == 12
    frames = tmp_path / "frames"
    assert main(["progressive", *SPLAT[1:], *view, "--steps", "2", "--scale-bar", "6", "-o", str(frames)]) == 0
    for name in ("frame_000.png", "frame_001.png"):
        assert bar_rows(decode_png(frames / name)[1], 255)[0] == 12
    capsys.readouterr()


def test_the_command_line_labels_in_the_inputs_unit(nifti, tmp_path):
    """A NIfTI in millimetres: the picture with ``--scale-bar 2`` is the one without it under the bar labelled in mm
    (not "units"), 2 mm long (the unit reaches the label; the label itself: the hand-written cases above)."""
    view = ["render", str(nifti), "--levels", "1", "--size", "96x120", "--extent", "12"]
    assert main(view + ["--scale-bar", "2", "-o", str(tmp_path / "a.png")]) == 0
    assert main(view + ["-o", str(tmp_path / "b.png")]) == 0
    (_, barred), (_, plain) = decode_png(tmp_path / "a.png"), decode_png(tmp_path / "b.png")
    assert bar_rows(barred, 255)[0] == 20  # 2 mm at 0.1 mm a pixel
    np.testing.assert_array_equal(barred, draw_scale_bar(plain, 0.1, "mm", 2.0))
    assert not np.array_equal(barred, draw_scale_bar(plain, 0.1, None, 2.0))


@pytest.mark.parametrize("argv, words", [
    (SPLAT + ["--scale-bar", "--perspective", "-o", "{}/a.png"], "--scale-bar needs an orthographic view"),
    (SPLAT + ["--scale-bar", "-o", "{}/a.tif"], "--scale-bar sets a .png's scale bar; a .tif holds the values"),
    (SPLAT + ["--scale-bar", "0", "-o", "{}/a.png"],
     "--scale-bar 0.0 must be a positive length in world units, e.g. 10, or left out (a fifth of the width)"),
    (SPLAT + ["--scale-bar", "inf", "-o", "{}/a.png"], "--scale-bar inf must be a positive length"),
    (SPLAT + ["--scale-bar", "100", "--extent", "48", "--size", "96", "-o", "{}/a.png"],
     "a scale bar of 100 units (200 pixels at 0.5 units a pixel) is longer than the"),
    (SPLAT + ["--scale-bar", "0.5", "--extent", "48", "--size", "96", "-o", "{}/a.png"],  # 48 units over 96 pixels
     "is under 2 pixels: give a length from 1 unit to 41 units, or no length (a fifth of the width: 5 units)"),
    (["progressive", *SPLAT[1:], "--scale-bar", "-o", "{}/a.gif", "--perspective"], "needs an orthographic view"),
])
def test_the_command_line_refusals_are_one_line(tmp_path, capsys, argv, words):
    """Exit 2 and one line; nothing written (a bar that does not fit refused before the render)."""
    assert main([a.format(tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1, err
    assert list(tmp_path.iterdir()) == []


def test_micrometre_label_is_drawn_with_glyphs_the_font_has(monkeypatch):
    """Pillow's bundled font has no µ (it drew its missing-glyph box): a micrometre bar's label is drawn as "um"."""
    from PIL import ImageFont

    import clwave.io.images as images
    font = ImageFont.load_default(size=20)
    assert font.getmask("µ").getbbox() == font.getmask("\uffff").getbbox()  # no glyph of its own
    picture = np.zeros((200, 300, 3), np.uint8)
    drawn = draw_scale_bar(picture, 10.0, unit="um", length=500)
    monkeypatch.setattr(images, "length_label", lambda length, unit, digits=6: "500 um")
    assert np.array_equal(drawn, draw_scale_bar(picture, 10.0, unit="um", length=500))


def test_a_result_in_angstroms_converts_to_the_unit_asked(tmp_path):
    """W2 (trial29): a result whose meta says Å, 5 Å a pixel.  ``unit="nm"``: a 10 nm bar is 20 pixels (10 nm over
    0.5 nm, not 10 "nm" over 5), pHYs 2e9 pixels a metre; no ``unit``: the result's own, the same pHYs and a default
    bar of a nice length in Å (200 Å of a 1500 Å wide picture: 40 pixels); on a result of no unit, ``unit=``
    declares the world unit, as before (50 nm: 10 pixels of 5 nm)."""
    import struct

    def angstroms():  # a splat of an MRC map (test_every_render_records_the_models_unit)
        result = flat(0.5, pixel=5.0)
        result.meta["unit"] = "A"
        return result

    ppm = struct.pack(">IIB", 2_000_000_000, 2_000_000_000, 1)
    angstroms().save(tmp_path / "nm.png", window=(0, 1), scale_bar=10.0, unit="nm")
    chunks, picture = decode_png(tmp_path / "nm.png")
    assert bar_rows(picture, 255)[0] == 20 and dict(chunks)[b"pHYs"] == ppm
    angstroms().save(tmp_path / "own.png", window=(0, 1), scale_bar=True)
    chunks, picture = decode_png(tmp_path / "own.png")
    assert bar_rows(picture, 255)[0] == 40 and dict(chunks)[b"pHYs"] == ppm
    np.testing.assert_array_equal(picture, flat(0.5, pixel=0.5).picture(window=(0, 1), scale_bar=20.0, unit="nm"))
    flat(0.5, pixel=5.0).save(tmp_path / "declared.png", window=(0, 1), scale_bar=50.0, unit="nm")
    chunks, picture = decode_png(tmp_path / "declared.png")
    assert bar_rows(picture, 255)[0] == 10 and dict(chunks)[b"pHYs"] == struct.pack(">IIB", 200_000_000,
                                                                                     200_000_000, 1)
    with pytest.raises(InputError, match="unit='nanometre' must be the world unit"):
        angstroms().picture(scale_bar=True, unit="nanometre")


def test_every_render_records_the_models_unit():
    """W2 (trial29): splat, raytrace, progressive and turntable results carry the model's unit (their scale bar's
    and pHYs' own), a model of no unit None."""
    import clwave

    data = np.zeros((8, 8, 8), np.float32)
    data[2:6, 2:6, 2:6] = 1.0
    camera = Camera(30, 20, (16, 16))
    for unit in ("A", None):
        wv = clwave.WaveletVolume.from_volume(clwave.Volume(data, spacing=(2.0,) * 3, unit=unit), levels=1)
        results = [clwave.splat(wv, camera), clwave.raytrace(wv, camera, absorption=False, tolerance=1e-2),
                   *clwave.progressive(wv, camera, steps=2), clwave.turntable(wv, 2, camera)]
        assert [r.meta["unit"] for r in results] == [unit] * len(results)


def test_a_scale_bar_without_roll_lies_along_x_and_y_only():
    """signed30 (trial30's finding 10): a vertical exaggeration is an exaggerated z spacing, and the bar stays true
    because an orbit camera's horizontal u has no z part at any azimuth and elevation without a roll; a roll tilts it
    into z (docs/coordinates.md §3)."""
    rng = np.random.default_rng(30)
    for azimuth, elevation in [(0, 0), (30, 20), (0, 90), (123, -60), *rng.uniform((-360, -90), (360, 90), (20, 2))]:
        _, u, _ = Camera(azimuth, elevation, size=8).basis()
        assert u[2] == 0 and np.hypot(u[0], u[1]) == pytest.approx(1, abs=1e-12)
    _, u, _ = Camera(30, 20, size=8, roll=30).basis()
    assert abs(u[2]) == pytest.approx(np.sin(np.radians(30)) * np.cos(np.radians(20)), abs=1e-12)
