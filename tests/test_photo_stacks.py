"""Folders of PNG or JPEG slices (photographs, one file a slice) read as TIFF slice folders are: natural name order,
spacing 1, one size, mode and sample type, one format (clwave/io/loaders/slices.py, docs/coordinates.md §1)."""

import json
import struct
import zlib
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
import tifffile

from clwave.cli import main
from clwave.errors import FileFormatError
from clwave.io.loaders import describe, load
from test_loaders import assert_one_line_error


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def write_slices(folder, slices, suffix, order=None):
    folder.mkdir(exist_ok=True)
    for z in order if order is not None else range(len(slices)):
        iio.imwrite(folder / f"s{z + 1}{suffix}", slices[z])
    return folder


def png_16bit_rgb(path, image):
    """A 16-bit RGB PNG written by hand (Pillow writes none): IHDR of colour type 2, depth 16; rows unfiltered."""
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    height, width, _ = image.shape
    rows = b"".join(b"\0" + row.astype(">u2").tobytes() for row in image)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 16, 2, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b""))


@pytest.mark.parametrize("channels", [None, 3, 4])
def test_a_png_folder_is_its_slices_in_natural_order(tmp_path, rng, channels):
    """Grey, RGB and RGBA: exact, slice 2 before slice 10 whatever the order the files were written in."""
    shape = (12, 5, 7) + ((channels,) if channels else ())
    slices = rng.integers(0, 256, shape).astype(np.uint8)
    folder = write_slices(tmp_path / "png", slices, ".png", order=rng.permutation(len(slices)))
    (folder / "notes.txt").write_text("not a slice")
    volume = load(folder)
    np.testing.assert_array_equal(volume.data, slices)
    assert volume.channels == (channels or 1) and volume.spacing == (1.0, 1.0, 1.0)
    assert load(folder, spacing=(3.0, 0.5, 0.5)).spacing == (3.0, 0.5, 0.5)


def test_a_16_bit_grey_png_folder_keeps_its_16_bits(tmp_path, rng):
    slices = rng.integers(0, 65536, (3, 6, 5)).astype(np.uint16)
    np.testing.assert_array_equal(load(write_slices(tmp_path / "png", slices, ".png")).data, slices)


def test_a_16_bit_colour_png_is_refused_not_read_as_8_bits(tmp_path, rng):
    """Pillow reads a 16-bit RGB PNG as 8 bits: refused in one line naming the slice and the way out."""
    folder = tmp_path / "png"
    folder.mkdir()
    image = rng.integers(0, 65536, (4, 5, 3)).astype(np.uint16)
    for z in (1, 2):
        png_16bit_rgb(folder / f"s{z}.png", image)
    with pytest.raises(FileFormatError, match=r"s1\.png is a 16-bit RGB PNG.*16-bit TIFF") as excinfo:
        load(folder)
    assert_one_line_error(excinfo)


def test_a_jpeg_folder_is_what_imageio_decodes(tmp_path, rng):
    """JPEG is lossy: the volume is what imageio decodes from each file (to the bit), not the source."""
    smooth = np.linspace(0, 150, 8)[None, :, None] + np.linspace(0, 50, 6)[:, None, None] + np.zeros(3)
    slices = np.stack([smooth + 5 * z for z in range(4)]).astype(np.uint8)
    folder = write_slices(tmp_path / "jpg", slices, ".jpg")
    volume = load(folder)
    decoded = np.stack([iio.imread(folder / f"s{z + 1}.jpg") for z in range(4)])
    np.testing.assert_array_equal(volume.data, decoded)


@pytest.mark.parametrize("suffix", [".png", ".jpg"])
def test_each_slice_is_opened_for_its_header_then_once_for_its_pixels(tmp_path, rng, monkeypatch, suffix):
    """Its mode, a PNG's bit depth, its declared size and its pixels from one open file (until tidy22 imageio's meta,
    the PNG header, its properties and its pixels opened it four times), after every slice's header (their sizes
    checked before any is read, ``clwave info`` too: loose30); the volume what imageio decodes."""
    import builtins

    slices = rng.integers(0, 256, (3, 5, 4, 3)).astype(np.uint8)
    folder = write_slices(tmp_path / "s", slices, suffix)
    opened, real_open = [], builtins.open

    def counting_open(file, *args, **kwargs):
        if str(file).startswith(str(folder)):
            opened.append(Path(file).name)
        return real_open(file, *args, **kwargs)
    monkeypatch.setattr(builtins, "open", counting_open)
    volume = load(folder)
    monkeypatch.undo()
    assert opened == [f"s{z}{suffix}" for z in (1, 2, 3)] * 2, opened
    np.testing.assert_array_equal(volume.data, [iio.imread(folder / f"s{z}{suffix}") for z in (1, 2, 3)])


RGB = np.zeros((6, 7, 3), np.uint8)


@pytest.mark.parametrize("first, odd, needle", [
    (RGB, RGB[..., 0], r"s2\.png has shape \(6, 7\) of uint8 but s1\.png has \(6, 7, 3\) of uint8"),
    (RGB, RGB[:5], r"s2\.png has shape \(5, 7, 3\)"),
    (RGB[..., 0], RGB[..., 0].astype(np.uint16),
     r"s2\.png has shape \(6, 7\) of uint16 but s1\.png has \(6, 7\) of uint8"),
])
def test_a_slice_of_another_size_mode_or_depth_is_refused_by_name(tmp_path, first, odd, needle):
    folder = write_slices(tmp_path / "png", [first] * 3, ".png")
    iio.imwrite(folder / "s2.png", odd)
    with pytest.raises(FileFormatError, match=needle) as excinfo:
        load(folder)
    assert_one_line_error(excinfo)


def test_a_tiff_slice_of_another_sample_type_is_refused_not_cast(tmp_path):
    """Until photo21 a uint16 slice of 300 after a uint8 one was cast into uint8 (read as 44)."""
    tifffile.imwrite(tmp_path / "s1.tif", np.zeros((4, 5), np.uint8))
    tifffile.imwrite(tmp_path / "s2.tif", np.full((4, 5), 300, np.uint16))
    with pytest.raises(FileFormatError,
                       match=r"s2\.tif has shape \(4, 5\) of uint16 but s1\.tif has \(4, 5\) of uint8"):
        load(tmp_path)


def test_a_png_stack_is_weighed_after_its_first_slice(tmp_path, monkeypatch):
    """As a TIFF folder: the first slice and the number of files declare the stack, weighed before the rest."""
    from clwave.io.loaders import slices

    folder = write_slices(tmp_path / "png", [np.zeros((6, 7, 4), np.uint8)] * 5, ".png")
    read, declared, real = [], [], slices._image_slice
    monkeypatch.setattr(slices, "_image_slice", lambda path: read.append(path.name) or real(path))

    def fits(voxels, channels):
        declared.append((voxels, channels))
        raise FileFormatError("refused")

    with pytest.raises(FileFormatError, match="refused"):
        load(folder, fits=fits)
    assert declared == [(5 * 6 * 7, 4)] and read == ["s1.png"]


def test_a_folder_mixing_formats_is_refused_naming_them(tmp_path, rng):
    folder = write_slices(tmp_path / "mixed", rng.integers(0, 256, (2, 4, 5)).astype(np.uint8), ".png")
    tifffile.imwrite(folder / "s3.tif", np.zeros((4, 5), np.uint8))
    iio.imwrite(folder / "s4.jpeg", np.zeros((4, 5), np.uint8))
    with pytest.raises(FileFormatError, match=r"mixes slices of TIFF and PNG and JPEG \(e\.g\. s3\.tif, s1\.png, "
                                              r"s4\.jpeg\)") as excinfo:
        load(folder)
    assert_one_line_error(excinfo)


def test_a_cmyk_jpeg_is_refused(tmp_path):
    from PIL import Image

    (tmp_path / "jpg").mkdir()
    Image.new("CMYK", (5, 4)).save(tmp_path / "jpg" / "s1.jpg")
    with pytest.raises(FileFormatError, match=r"s1\.jpg is a CMYK image; clwave reads grey, RGB and RGBA"):
        load(tmp_path / "jpg")


def test_info_and_render_of_a_png_folder(tmp_path, capsys, rng):
    folder = write_slices(tmp_path / "png", rng.integers(0, 256, (5, 6, 7, 3)).astype(np.uint8), ".png")
    assert describe(folder)["stored_shape"] == [5, 6, 7, 3]
    code, out, err = run(capsys, "info", str(folder), "--json")
    assert code == 0, err
    facts = json.loads(out)
    assert (facts["format"], facts["stored_shape"], facts["dtype"]) == ("png-folder", [5, 6, 7, 3], "uint8")
    code, out, err = run(capsys, "render", str(folder), "--levels", "1", "--size", "8", "-o", str(tmp_path / "r.png"))
    assert code == 0, err
    assert iio.imread(tmp_path / "r.png").shape[:2] == (8, 8)


def test_slices_read_as_photographed_from_minus_z(tmp_path, capsys):
    """Row 0 of a slice lies at world -y, its columns along +x: seen from -z (azimuth -90, elevation -90) u = +x and
    v = -y, so an "F" drawn in the slices reads as in an image viewer; from +z (elevation 90) it is upside down."""
    letter = np.zeros((16, 16), np.uint8)
    letter[2:14, 4:7] = letter[2:5, 4:12] = letter[7:9, 4:10] = 255
    folder = write_slices(tmp_path / "F", [letter] * 4, ".png")
    seen = {}
    for elevation in (-90, 90):
        raw = tmp_path / f"r{elevation}.npy"
        code, _, err = run(capsys, "render", str(folder), "--azimuth", "-90", "--elevation", str(elevation),
                           "--fit", "box", "--size", "16", "--levels", "1", "-o", str(tmp_path / f"r{elevation}.png"),
                           "--raw", str(raw))
        assert code == 0, err
        image = np.load(raw)[..., 0]
        seen[elevation] = {name: np.corrcoef(image.ravel(), flipped.ravel())[0, 1] for name, flipped in
                           (("as drawn", letter), ("upside down", letter[::-1]), ("mirrored", letter[:, ::-1]),
                            ("turned", letter[::-1, ::-1]))}
    assert max(seen[-90], key=seen[-90].get) == "as drawn", seen
    assert max(seen[90], key=seen[90].get) == "upside down", seen


def test_a_dicom_series_with_a_preview_jpeg_is_read_as_the_series(tmp_path, rng):
    """A DICOM series exported with its previews (a JPEG or PNG beside the slices, named or not as .dcm) is read as
    the series, as before PNG and JPEG folders were read: the images are its previews, not the volume."""
    from pydicom.uid import generate_uid

    from test_loaders import axial, write_series

    for names in (["s1.dcm", "s2.dcm", "s3.dcm"], ["IM1", "IM2", "IM3"]):
        folder = tmp_path / names[0]
        folder.mkdir()
        stored = write_series(folder, rng, axial(0.0, 2.5, 5.0), generate_uid(), names)
        iio.imwrite(folder / "preview.jpg", np.zeros((16, 16, 3), np.uint8))
        assert load(folder, progress_bar=False).shape == stored.shape
