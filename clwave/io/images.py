"""Writing pictures and float images (docs/coordinates.md §3): PNG of 8 bits a sample (Pillow) or 16 (pypng: Pillow
and imageio's Pillow plugin write no 16-bit colour PNG), tagged sRGB, with the physical pixel size (pHYs) where the
world unit is a length; TIFF of the float32 values as rendered (tifffile), its pixel size in the resolution tags.
"""

from __future__ import annotations

import io
from fractions import Fraction

import numpy as np

from ..errors import InputError

#: the output suffixes of a picture (PNG) and of the float image (TIFF)
PNG_SUFFIXES, TIFF_SUFFIXES = (".png",), (".tif", ".tiff")
#: the world units a pixel size is written in, and their length in metres
UNIT_METRES = {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6, "nm": 1e-9, "A": 1e-10}  # A: the ångström
BIT_DEPTHS = (8, 16)

_SRGB = (b"sRGB", b"\x00")  # perceptual rendering intent


def check_bit_depth(bit_depth) -> int:
    """``bit_depth`` (None: 8) as 8 or 16; one InputError otherwise."""
    if bit_depth is None:
        return 8
    if isinstance(bit_depth, bool) or not isinstance(bit_depth, (int, np.integer)) or bit_depth not in BIT_DEPTHS:
        raise InputError(f"bit_depth={bit_depth!r} must be 8 or 16 (bits a sample of a PNG)",
                         cli=f"--bit-depth {bit_depth} must be 8 or 16")
    return int(bit_depth)


def check_unit(unit):
    """``unit`` (None: not a known length) as one of :data:`UNIT_METRES`; one InputError otherwise."""
    if unit is not None and unit not in UNIT_METRES:
        raise InputError(f"unit={unit!r} must be the world unit, one of {', '.join(UNIT_METRES)}, or None where it "
                         f"is not a known length")
    return unit


def pixel_size(meta) -> tuple | None:
    """The ``(x, y)`` world size of a pixel of the image of ``meta`` (a render's): a cone beam's detector spacing
    (columns, rows), else the square pixel at the camera's target (``meta["pixel"]``); None where it has neither."""
    camera = meta.get("camera") or {}
    if camera.get("kind") == "cone_beam":
        from ..model.conebeam import ConeBeam

        rows, columns = ConeBeam.from_dict(camera).pixel
        return float(columns), float(rows)
    pixel = meta.get("pixel")
    return None if pixel is None else (float(pixel), float(pixel))


def write_png(fh, picture, size=None, unit=None):
    """Write ``picture`` (uint8 or uint16; (H, W) grey, (H, W, 3) RGB or (H, W, 4) RGBA with straight alpha) to the
    binary file ``fh`` as PNG, tagged sRGB, with pHYs where ``size`` (x, y) is in a ``unit`` of length."""
    per = None if unit is None else _per_unit(size, unit, 1.0)  # pHYs' "unknown unit" is an aspect ratio alone
    ppm = None if per is None else [round(p) for p in per]
    if ppm is not None and not all(1 <= p < 1 << 32 for p in ppm):
        ppm = None  # pHYs holds whole pixels per metre in 32 bits
    if picture.dtype == np.uint8:
        from PIL import Image, PngImagePlugin

        info = PngImagePlugin.PngInfo()
        info.add(*_SRGB)
        dpi = {} if ppm is None else dict(dpi=tuple(p * 0.0254 for p in ppm))  # Pillow's pHYs: dpi, stored per metre
        Image.fromarray(picture).save(fh, format="PNG", pnginfo=info, **dpi)
        return
    import png

    height, width = picture.shape[:2]
    planes = 1 if picture.ndim == 2 else picture.shape[2]
    physical = {} if ppm is None else dict(x_pixels_per_unit=ppm[0], y_pixels_per_unit=ppm[1], unit_is_meter=True)
    writer = png.Writer(width, height, greyscale=planes < 3, alpha=planes == 4, bitdepth=16, **physical)
    rows = picture.reshape(height, width * planes).astype(">u2")
    written = io.BytesIO()
    writer.write_packed(written, (row.tobytes() for row in rows))
    header, *chunks = png.Reader(bytes=written.getvalue()).chunks()
    png.write_chunks(fh, [header, _SRGB, *chunks])  # pypng writes no sRGB chunk: it goes after IHDR


def write_tiff(fh, image, size=None, unit=None, alpha=False, shape=None):
    """Write the float32 ``image`` ((H, W) or (H, W, C); or with ``shape`` (N, H, W) a stack, an iterator of its
    (H, W) pages) to the binary file ``fh`` as TIFF: 3 channels RGB, 4 with ``alpha`` RGB and associated
    (premultiplied) alpha, others samples of a grey image; ``size`` (x, y) the pixel's size in ``unit``, written as
    pixels per centimetre (per world unit, resolution unit NONE, where ``unit`` is None)."""
    import tifffile

    channels = 1 if shape is not None or image.ndim == 2 else image.shape[2]
    options = dict(photometric="minisblack")
    if channels == 3 or (channels == 4 and alpha):
        options = dict(photometric="rgb", extrasamples=[1] if alpha else [])
    elif channels > 1:
        options.update(planarconfig="contig", extrasamples=[0] * (channels - 1))
    per = _per_unit(size, unit, 1.0 if unit is None else 0.01)
    most = (1 << 32) - 2  # TIFF's rationals: 32-bit terms
    ratios = None if per is None else [Fraction(p).limit_denominator(max(1, int(most / max(p, 1.0)))) for p in per]
    if ratios is not None and all(0 < r.numerator <= most for r in ratios):
        options.update(resolution=tuple((r.numerator, r.denominator) for r in ratios),
                       resolutionunit="NONE" if unit is None else "CENTIMETER")
    named = tifffile.FileHandle(fh, name="image.tif")  # tifffile splits a file's name: an unnamed file's is a number
    tifffile.imwrite(named, image, shape=shape, dtype=np.float32 if shape is not None else None, **options)


def _per_unit(size, unit, counted_in) -> list | None:
    """Pixels per length ``counted_in`` (metres; with ``unit`` None, world units) along x and y of pixels of
    ``size`` (x, y) in ``unit``; None where there is no size, or no positive finite count (a pixel of 0, NaN or
    1e-320 world units: no tag rather than a wrong one)."""
    if size is None:
        return None
    length = 1.0 if unit is None else UNIT_METRES[unit]
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        per = [float(np.float64(counted_in) / (np.float64(s) * length)) for s in size]
    return per if all(0.0 < p < np.inf for p in per) else None
