"""Pictures users publish and measure (docs/coordinates.md §4): 16-bit PNG, float TIFF, transparent PNG, the pixel
size and sRGB chunks; each read back by a reader other than the writer (Pillow, tifffile, and the PNG decoder here),
its integers against a NumPy formula of the float image."""

import errno
import json
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
import tifffile
from PIL import Image

import clwave
from clwave.cli import main
from clwave.errors import InputError
from clwave.io.result import RenderResult

SPLAT = ["render", "phantom:hydrogen:16", "--levels", "1", "--size", "12x10"]
SHADED = SPLAT + ["--method", "raytrace", "--tf", "hydrogen"]


def decode_png(path) -> tuple:
    """``(chunks, pixels)`` of a non-interlaced grey, RGB or RGBA PNG of 8 or 16 bits: its chunks as [(type, data)]
    (their CRCs checked) and its samples (H, W[, C]) unfiltered by the PNG specification (§9), independently of
    Pillow and pypng."""
    data = Path(path).read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    chunks, at = [], 8
    while at < len(data):
        length, kind = struct.unpack(">I4s", data[at:at + 8])
        body = data[at + 8:at + 8 + length]
        assert struct.unpack(">I", data[at + 8 + length:at + 12 + length])[0] == zlib.crc32(kind + body)
        chunks.append((kind, body))
        at += 12 + length
    width, height, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", chunks[0][1])
    assert chunks[0][0] == b"IHDR" and chunks[-1][0] == b"IEND" and interlace == 0 and depth in (8, 16)
    planes = {0: 1, 2: 3, 6: 4}[colour]
    step = planes * depth // 8  # bytes a pixel
    raw = zlib.decompress(b"".join(body for kind, body in chunks if kind == b"IDAT"))
    stride = width * step
    rows, previous = [], bytearray(stride)
    for r in range(height):
        kind, line = raw[r * (stride + 1)], bytearray(raw[r * (stride + 1) + 1:(r + 1) * (stride + 1)])
        for i in range(stride):
            a, b = line[i - step] if i >= step else 0, previous[i]
            c = previous[i - step] if i >= step else 0
            p = a + b - c
            paeth = a if abs(p - a) <= abs(p - b) and abs(p - a) <= abs(p - c) else b if abs(p - b) <= abs(p - c) else c
            line[i] = (line[i] + (0, a, b, (a + b) // 2, paeth)[kind]) & 0xFF
        rows.append(bytes(line))
        previous = line
    pixels = np.frombuffer(b"".join(rows), ">u2" if depth == 16 else np.uint8).reshape(height, width, planes)
    return chunks, pixels[..., 0] if planes == 1 else pixels


def srgb(linear):
    """The sRGB encoding (IEC 61966-2-1) of linear light in 0..1."""
    linear = np.asarray(linear, np.float64)
    return np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)


def window_levels(values, lo, hi, top):
    """The integers of ``values`` through the window (lo, hi) on 0..top: of 8 bits in float32, the image's own
    precision, of 16 in float64 (where float32's rounding would move levels near their ties)."""
    values = np.asarray(values, np.float32 if top < 256 else np.float64)
    return np.round(top * np.clip((values - lo) / (hi - lo), 0, 1)).astype(np.int64)


def chunk_types(chunks) -> list:
    return [kind for kind, _ in chunks]


@pytest.mark.parametrize("bits", [8, 16])
def test_a_grey_png_holds_the_window_of_the_raw_values(tmp_path, bits):
    """``render -o a.png --bit-depth N --raw a.npy --window LO,HI``: each sample is round((2^N - 1) clip((v - LO) /
    (HI - LO))) of the raw value, read back by Pillow and by the decoder here; sRGB tagged; a phantom's world unit is
    no length: no pHYs."""
    png, raw = tmp_path / "a.png", tmp_path / "a.npy"
    assert main(SPLAT + ["-o", str(png), "--raw", str(raw), "--window", "0.01,1.2", "--bit-depth", str(bits)]) == 0
    values = np.load(raw)[..., 0]
    want = window_levels(values, 0.01, 1.2, (1 << bits) - 1)
    assert want.max() == (1 << bits) - 1 and len(np.unique(want)) > 10  # the window cuts some values, not all
    chunks, pixels = decode_png(png)
    np.testing.assert_array_equal(pixels, want)
    with Image.open(png) as im:
        assert im.mode == ("L" if bits == 8 else "I;16") and im.info.get("srgb") == 0 and "dpi" not in im.info
        np.testing.assert_array_equal(np.asarray(im), want)
    assert chunk_types(chunks)[:2] == [b"IHDR", b"sRGB"] and b"pHYs" not in chunk_types(chunks)


def test_colour_pictures_of_16_bits_read_back(tmp_path):
    """An X-ray of three channels as 16-bit RGB, a shaded image as 16-bit RGBA (transparent) and RGB over a
    background: the integers the decoder here reads are the NumPy formulas' (Pillow reads 16-bit colour as 8 bits,
    its high bytes)."""
    rng = np.random.default_rng(5)
    xray = RenderResult(rng.random((5, 7, 3)).astype(np.float32) * 3, dict(mode="xray"))
    xray.save(tmp_path / "x.png", window=(0.5, 2.5), bit_depth=16)
    _, pixels = decode_png(tmp_path / "x.png")
    np.testing.assert_array_equal(pixels, window_levels(xray.image, 0.5, 2.5, 65535))
    with Image.open(tmp_path / "x.png") as im:
        assert im.mode == "RGB" and im.info.get("srgb") == 0
        np.testing.assert_array_equal(np.asarray(im), pixels >> 8)

    alpha = rng.random((5, 7, 1)).astype(np.float32)
    alpha[0, 0] = 0.0  # nothing there: no colour either
    colour = rng.random((5, 7, 3)).astype(np.float32)
    shaded = RenderResult(np.concatenate([colour * alpha, alpha], -1), dict(mode="emission-absorption"))
    shaded.save(tmp_path / "t.png", background="transparent", bit_depth=16)
    _, pixels = decode_png(tmp_path / "t.png")
    straight = np.where(alpha > 0, (colour * alpha).astype(np.float64) / np.maximum(alpha, 1e-30), 0.0)
    np.testing.assert_array_equal(pixels[..., 3], np.round(65535 * alpha[..., 0].astype(np.float64)))
    np.testing.assert_array_equal(pixels[..., :3], np.round(65535 * srgb(np.clip(straight, 0, 1))))
    assert pixels[0, 0].tolist() == [0, 0, 0, 0]
    shaded.save(tmp_path / "w.png", background=(1.0, 0.5, 0.0), bit_depth=16)
    _, pixels = decode_png(tmp_path / "w.png")
    over = (colour * alpha).astype(np.float64) + (1 - alpha.astype(np.float64)) * np.array([1.0, 0.5, 0.0])
    np.testing.assert_array_equal(pixels, np.round(65535 * srgb(np.clip(over, 0, 1))))


@pytest.mark.parametrize("bits", [8, 16])
def test_transparent_alpha_and_colour_of_a_slab_are_the_closed_form(bits, tmp_path):
    """A premultiplied image of colour c and opacity a (emission c a, the image of a uniform slab) written
    transparent is straight alpha: the PNG holds round(top srgb(c)) and round(top a) exactly; a luminous pixel
    (colour above its opacity: light added) is clipped to full colour."""
    c, a = np.array([0.8, 0.35, 0.05]), 0.62
    image = np.zeros((2, 3, 4), np.float32)
    image[...] = np.append(c * a, a)
    image[1, 2] = (0.9, 0.3, 0.2, 0.5)  # R above alpha: light added
    RenderResult(image, dict(mode="emission-absorption")).save(tmp_path / "s.png", background="transparent",
                                                               bit_depth=bits)
    top = (1 << bits) - 1
    _, pixels = decode_png(tmp_path / "s.png")
    want = np.append(np.round(top * srgb(c)), round(top * a))
    assert pixels[0, 0].tolist() == want.tolist() and (pixels[:, :2] == pixels[0, 0]).all()
    assert pixels[1, 2].tolist() == np.round(top * np.append(srgb([1.0, 0.6, 0.4]), 0.5)).tolist()


def test_a_ray_traced_slab_over_transparency(tmp_path):
    """A Haar slab of opacity density s (per world unit) and emission c s, length L, ray traced without shading:
    alpha 1 - e^{-s L} and straight colour c (docs/raytracing.md §2), read back by Pillow as 8-bit RGBA within the
    tracer's tolerance, which the values below keep clear of a rounding boundary."""
    n, s, dx = 6, 0.05, 3.0
    levels = np.array([230.0, 140.0, 60.0])
    c = ((levels / 255 + 0.055) / 1.055) ** 2.4  # the linear light whose sRGB levels these are (all above 10)
    alpha = 1 - np.exp(-s * n * dx)
    want = np.append(255 * srgb(c), 255 * alpha)
    assert np.all(np.abs(want - np.round(want)) < 0.4)  # clear of x.5 by 0.1 of a level
    data = np.concatenate([np.broadcast_to(c * s, (4, 4, n, 3)), np.full((4, 4, n, 1), s)], -1)
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data.astype(np.float32), spacing=(1.0, 1.0, dx)),
                                          wavelet="haar", levels=1)
    result = clwave.RayTracer(wv).render(clwave.Camera(0, 0, size=2, extent=1.0), tolerance=1e-5, shading=False)
    result.save(tmp_path / "slab.png", background="transparent")
    with Image.open(tmp_path / "slab.png") as im:
        assert im.mode == "RGBA"
        pixels = np.asarray(im)
    assert (pixels == np.round(want)).all(), (pixels[0, 0], want)


def test_float_tiff_of_an_xray_and_a_shaded_image(tmp_path):
    """``-o a.tif``: the float32 image as rendered, read back by tifffile: the --raw values, an X-ray grey, a shaded
    image RGB with associated (premultiplied) alpha; the pixel's size as the resolution (per world unit, unit none:
    a phantom's unit is no length); --stats records no window."""
    for argv, name in ((SPLAT, "x"), (SHADED, "s")):
        tif, raw, stats = (tmp_path / f"{name}{suffix}" for suffix in (".tif", ".npy", ".json"))
        assert main(argv + ["-o", str(tif), "--stats", str(stats)]) == 0
        assert main(argv + ["-o", str(tmp_path / f"{name}.png"), "--raw", str(raw)]) == 0
        meta = json.loads(stats.read_text())
        with tifffile.TiffFile(tif) as t:
            page = t.pages[0]
            values = page.asarray()
            assert page.dtype == np.float32 and meta["window"] is None
            x, y = (page.tags[k].value for k in ("XResolution", "YResolution"))
            assert page.tags["ResolutionUnit"].value == 1 and x == y
            assert x[0] / x[1] == pytest.approx(1 / meta["pixel"], rel=1e-9)
            if name == "x":
                assert values.shape == (12, 10) and page.photometric == tifffile.PHOTOMETRIC.MINISBLACK
                np.testing.assert_array_equal(values, np.load(raw)[..., 0])
            else:
                assert values.shape == (12, 10, 4) and page.photometric == tifffile.PHOTOMETRIC.RGB
                assert page.extrasamples == (tifffile.EXTRASAMPLE.ASSOCALPHA,)
                np.testing.assert_array_equal(values, np.load(raw))


@pytest.fixture(scope="module")
def nifti(tmp_path_factory):
    """A 12 x 10 x 8 NIfTI of a bright cube in a dim box, 0.5 mm voxels (its world unit millimetres)."""
    import nibabel

    data = np.full((12, 10, 8), 0.1, np.float32)
    data[3:9, 3:7, 2:6] = 1.0
    path = tmp_path_factory.mktemp("nifti") / "cube.nii"
    nibabel.save(nibabel.Nifti1Image(data, np.diag([0.5, 0.5, 0.5, 1.0])), path)
    return path


def test_millimetre_inputs_give_the_physical_pixel_size(nifti, tmp_path):
    """A NIfTI in mm: the PNG's pHYs is round(1000 / pixel) pixels per metre on both axes, unit metre (8 and 16
    bits, Pillow's dpi too), the TIFF's resolution 10 / pixel per centimetre."""
    base = ["render", str(nifti), "--levels", "1", "--size", "9", "--stats", str(tmp_path / "m.json"), "--force"]
    for bits in ("8", "16"):
        assert main(base + ["-o", str(tmp_path / "m.png"), "--bit-depth", bits]) == 0
        pixel = json.loads((tmp_path / "m.json").read_text())["pixel"]
        chunks, _ = decode_png(tmp_path / "m.png")
        ppm = round(1000 / pixel)
        assert dict(chunks)[b"pHYs"] == struct.pack(">IIB", ppm, ppm, 1) and b"sRGB" in dict(chunks)
        with Image.open(tmp_path / "m.png") as im:
            assert im.info["dpi"] == pytest.approx((ppm * 0.0254,) * 2)
    assert main(base + ["-o", str(tmp_path / "m.tif")]) == 0
    with tifffile.TiffFile(tmp_path / "m.tif") as t:
        page = t.pages[0]
        x = page.tags["XResolution"].value
        assert page.tags["ResolutionUnit"].value == 3 and x[0] / x[1] == pytest.approx(10 / pixel, rel=1e-9)
    # --spacing re-states the numbers in the file's unit, mm (until trial25 it dropped it: no pHYs)
    assert main(base + ["-o", str(tmp_path / "n.png"), "--spacing", "1"]) == 0
    ppm = round(1000 / json.loads((tmp_path / "m.json").read_text())["pixel"])
    assert dict(decode_png(tmp_path / "n.png")[0])[b"pHYs"] == struct.pack(">IIB", ppm, ppm, 1)
    np.save(tmp_path / "u.npy", clwave.load(nifti).data)  # units of its own: no pHYs
    assert main(base[:1] + [str(tmp_path / "u.npy")] + base[2:] + ["-o", str(tmp_path / "u.png")]) == 0
    assert b"pHYs" not in chunk_types(decode_png(tmp_path / "u.png")[0])


def test_drr_as_a_float_tiff_stack_and_a_16_bit_png(nifti, tmp_path):
    """``drr -o s.tif``: one float32 page a pose, the .npy's values, the detector's spacing (columns, rows) as the
    resolution per centimetre; one pose as a 16-bit PNG of its window."""
    (tmp_path / "p.csv").write_text("azimuth,elevation\n0,0\n70,15\n")
    base = ["drr", str(nifti), "--levels", "1", "--poses", str(tmp_path / "p.csv"), "--size", "6x8",
            "--pixel", "0.4,0.25", "--dso", "60", "--dsd", "90"]
    assert main(base + ["-o", str(tmp_path / "s.tif")]) == 0
    assert main(base + ["-o", str(tmp_path / "s.npy")]) == 0
    with tifffile.TiffFile(tmp_path / "s.tif") as t:
        assert len(t.pages) == 2
        np.testing.assert_array_equal(t.asarray(), np.load(tmp_path / "s.npy"))
        for page in t.pages:
            x, y = (page.tags[k].value for k in ("XResolution", "YResolution"))
            assert page.tags["ResolutionUnit"].value == 3
            assert (x[0] / x[1], y[0] / y[1]) == pytest.approx((10 / 0.25, 10 / 0.4), rel=1e-9)
    (tmp_path / "p.csv").write_text("azimuth,elevation\n70,15\n")
    assert main(base + ["-o", str(tmp_path / "one.png"), "--bit-depth", "16", "--window", "0,2"]) == 0
    chunks, pixels = decode_png(tmp_path / "one.png")
    np.testing.assert_array_equal(pixels, window_levels(np.load(tmp_path / "s.npy")[1], 0.0, 2.0, 65535))
    ppm = (round(1000 / 0.25), round(1000 / 0.4))
    assert dict(chunks)[b"pHYs"] == struct.pack(">IIB", *ppm, 1)


def test_progressive_frames_of_16_bits(tmp_path):
    """``progressive -o FOLDER --bit-depth 16``: every frame a 16-bit grey PNG."""
    assert main(["progressive", "phantom:hydrogen:16", "--levels", "1", "--size", "8", "--steps", "2",
                 "--window", "0,1", "--bit-depth", "16", "-o", str(tmp_path / "f")]) == 0
    frames = sorted((tmp_path / "f").iterdir())
    assert len(frames) == 2
    for frame in frames:
        _, pixels = decode_png(frame)
        assert pixels.dtype == ">u2" and pixels.shape == (8, 8)  # 16-bit grey (the decoder's IHDR)


@pytest.mark.parametrize("argv, words", [
    (SPLAT + ["--turntable", "2", "-o", "{}/t.gif", "--bit-depth", "16"], "--bit-depth 16 is for PNG; a GIF holds 8"),
    (SHADED + ["--turntable", "2", "-o", "{}/t.gif", "--background", "transparent"],
     "--background transparent is for PNG; a GIF has no partial transparency"),
    (["progressive", "phantom:hydrogen:16", "--levels", "1", "--size", "8", "-o", "{}/p.gif", "--bit-depth", "16"],
     "a GIF holds 8 bits a sample: leave it out, or write PNG frames to a folder"),
    (SHADED + ["--xray", "-o", "{}/a.png", "--background", "transparent"], "--background is for a shaded volume"),
    (SPLAT + ["-o", "{}/a.png", "--background", "transparent"], "--background is for --method raytrace"),
    (SPLAT + ["-o", "{}/a.jpg"], "-o {}/a.jpg must end in .png or .tif or .tiff"),
    (SPLAT + ["-o", "{}/a.tif", "--bit-depth", "16"], "--bit-depth sets a .png's bit depth; a .tif holds the values"),
    (SPLAT + ["-o", "{}/a.tiff", "--window", "0,1"], "--window sets a .png's grey levels; a .tiff holds the values"),
    (SHADED + ["-o", "{}/a.tif", "--background", "1,1,1"], "--background sets a .png's background; a .tif holds"),
    (SPLAT + ["-o", "{}/a.png", "--bit-depth", "12"], "argument --bit-depth: invalid choice: 12"),
    (SHADED + ["-o", "{}/a.png", "--background", "clear"], "--background 'clear' must be 3 comma-separated numbers"),
    (["drr", "phantom:hydrogen:16", "--poses", "{}/p.csv", "-o", "{}/d.npy", "--bit-depth", "16"],
     "--bit-depth sets a .png's bit depth; a .npy holds the values themselves: leave it out"),
])
def test_bad_combinations_are_one_line(tmp_path, capsys, argv, words):
    """Exit 2 and one line naming the problem, before the input is read; nothing written."""
    (tmp_path / "p.csv").write_text("azimuth\n0\n")
    assert main([a.format(tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err
    assert words.format(tmp_path) in err and err.count("\n") == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.csv"]


def test_an_existing_tiff_needs_force_and_outputs_are_published_together(tmp_path, capsys, monkeypatch):
    """An existing .tif is refused without --force (its bytes kept); a failure at the last output (--stats) leaves
    neither the .tif nor --raw (all or none, io/files.py's Staging)."""
    target = tmp_path / "a.tif"
    target.write_bytes(b"precious")
    assert main(SPLAT + ["-o", str(target)]) == 2
    assert "--force" in capsys.readouterr().err and target.read_bytes() == b"precious"
    import clwave.io.result

    def full(fh):
        raise OSError(errno.ENOSPC, "No space left on device")

    def failing_json(path, writer, overwrite=False, _write=clwave.io.result.write_atomic):
        return _write(path, full if str(path).endswith(".json") else writer, overwrite)

    monkeypatch.setattr(clwave.io.result, "write_atomic", failing_json)
    new = tmp_path / "b.tif"
    assert main(SPLAT + ["-o", str(new), "--raw", str(tmp_path / "b.npy"), "--stats", str(tmp_path / "b.json")]) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.tif"]


def test_the_api_refuses_options_a_file_does_not_hold():
    """``save``: window=, background= and bit_depth= are a .png's; a bit depth other than 8 or 16, an unknown unit,
    and a transparent X-ray are refused in one line."""
    xray = RenderResult(np.ones((2, 2, 1), np.float32), dict(mode="xray"))
    with pytest.raises(InputError, match=r"^window= sets a \.png's picture; x\.tif holds the image's values: leave"):
        xray.save("x.tif", window=(0, 1))
    with pytest.raises(InputError, match=r"^bit_depth= sets a \.png's picture; x\.npy holds"):
        xray.save("x.npy", bit_depth=16)
    with pytest.raises(InputError, match=r"^bit_depth=12 must be 8 or 16"):
        xray.save("x.png", bit_depth=12)
    with pytest.raises(InputError, match=r"^unit='inch' must be the world unit, one of m, cm, mm, um"):
        xray.save("x.png", unit="inch")
    with pytest.raises(InputError, match=r"^background='transparent' is for a shaded image"):
        xray.picture(background="transparent")


def test_the_world_unit_of_an_input(tmp_path, nifti, rng, capsys):
    """``loaders.world_unit``: DICOM's mm; a NIfTI's xyzt_units (unknown taken as mm, as NIfTI readers do; micron
    um); a NRRD's space units, else mm where it names a space, else none; none for a .npy; an OME-TIFF's um, an ImageJ
    stack's unit (micron, µm, um: um).  A .clw records its input's unit (trial24 row 11): its render's pHYs and
    --stats give it."""
    import nibabel
    import nrrd

    from clwave.io.loaders import world_unit
    from test_loaders import write_series

    assert world_unit(nifti) == "mm"
    image = nibabel.load(nifti)
    image.header.set_xyzt_units("micron")
    nibabel.save(image, tmp_path / "um.nii")
    data = np.zeros((4, 5, 6), np.float32)
    nrrd.write(str(tmp_path / "lps.nrrd"), data, {"space": "left-posterior-superior", "space directions": np.eye(3)})
    nrrd.write(str(tmp_path / "um.nrrd"), data, {"space": "left-posterior-superior", "space directions": np.eye(3),
                                                 "space units": ["um", "um", "um"]})
    nrrd.write(str(tmp_path / "plain.nrrd"), data, {"spacings": [1.0, 1.0, 1.0]})
    np.save(tmp_path / "v.npy", data)
    (tmp_path / "ct").mkdir()
    write_series(tmp_path / "ct", rng, [(-20.0, 30.0, z) for z in (0, 1, 2)], "1.2.3", ["a", "b", "c"])
    assert [world_unit(tmp_path / name) for name in ("um.nii", "lps.nrrd", "um.nrrd", "plain.nrrd", "v.npy", "ct")] \
        == ["um", "mm", "um", None, None, "mm"]
    stack = np.zeros((4, 5, 6), np.uint16)
    tifffile.imwrite(tmp_path / "o.ome.tif", stack, ome=True, metadata={"axes": "ZYX", "PhysicalSizeX": 0.5})
    tifffile.imwrite(tmp_path / "plain.tif", stack, photometric="minisblack")
    units = ("micron", "\\u00B5m", "um", "mm", "pixel")  # µm as ImageJ writes it (its description is ASCII)
    for i, unit in enumerate(units):
        tifffile.imwrite(tmp_path / f"ij{i}.tif", stack, imagej=True, metadata={"unit": unit, "axes": "ZYX"})
    assert [world_unit(tmp_path / f"ij{i}.tif") for i in range(len(units))] == ["um", "um", "um", "mm", None]
    assert (world_unit(tmp_path / "o.ome.tif"), world_unit(tmp_path / "plain.tif")) == ("um", None)
    assert main(["compress", str(tmp_path / "um.nii"), "--levels", "1", "-o", str(tmp_path / "m.clw")]) == 0
    assert clwave.WaveletVolume.open(tmp_path / "m.clw").unit == "um"
    capsys.readouterr()
    assert main(["info", str(tmp_path / "m.clw")]) == 0 and " um (x, y, z), centre" in capsys.readouterr().out
    assert main(["info", str(tmp_path / "m.clw"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["unit"] == "um"
    assert main(["render", str(tmp_path / "m.clw"), "--size", "8", "-o", str(tmp_path / "m.png"), "--stats",
                 str(tmp_path / "m.json")]) == 0
    stats = json.loads((tmp_path / "m.json").read_text())
    ppm = round(1e6 / stats["pixel"])  # pixels per metre of a pixel of stats["pixel"] micrometres
    assert stats["unit"] == "um"
    assert dict(decode_png(tmp_path / "m.png")[0])[b"pHYs"] == struct.pack(">IIB", ppm, ppm, 1)


@pytest.mark.parametrize("channels", [2, 3, 4])
def test_a_tiff_of_several_xray_channels(tmp_path, channels):
    """An X-ray of 3 channels is a float RGB TIFF, of 2 or 4 grey with extra samples (not alpha): every value as
    rendered, read back by tifffile."""
    import tifffile

    image = np.random.default_rng(channels).random((3, 5, channels)).astype(np.float32)
    RenderResult(image, dict(mode="xray", pixel=0.5)).save(tmp_path / "x.tif")
    with tifffile.TiffFile(tmp_path / "x.tif") as t:
        page = t.pages[0]
        np.testing.assert_array_equal(page.asarray(), image)
        assert page.photometric == (tifffile.PHOTOMETRIC.RGB if channels == 3 else tifffile.PHOTOMETRIC.MINISBLACK)
        assert page.extrasamples == (() if channels == 3 else (tifffile.EXTRASAMPLE.UNSPECIFIED,) * (channels - 1))
        assert page.tags["XResolution"].value == (2, 1) and page.tags["ResolutionUnit"].value == 1
