"""Writing pictures and float images (docs/coordinates.md §3): PNG of 8 bits a sample (Pillow) or 16 (pypng: Pillow
and imageio's Pillow plugin write no 16-bit colour PNG), tagged sRGB, with the physical pixel size (pHYs) where the
world unit is a length, and a scale bar burnt in on request; TIFF of the float32 values as rendered (tifffile), its
pixel size in the resolution tags.
"""

from __future__ import annotations

import io
from fractions import Fraction
from pathlib import Path

import numpy as np

from ..errors import InputError
from .files import write_atomic

#: the output suffixes of a picture (PNG) and of the float image (TIFF)
PNG_SUFFIXES, TIFF_SUFFIXES = (".png",), (".tif", ".tiff")
#: the world units a pixel size is written in, and their length in metres
UNIT_METRES = {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6, "nm": 1e-9, "A": 1e-10}  # A: the ångström
#: the names of those units as inputs write them (lower case: xarray's and CF's units, NGFF's, ImageJ's), as clwave
#: names them (:func:`unit_named`, one table for every reader)
UNIT_NAMES = {"m": "m", "meter": "m", "metre": "m", "meters": "m", "metres": "m", "cm": "cm", "centimeter": "cm",
              "centimetre": "cm", "mm": "mm", "millimeter": "mm", "millimetre": "mm", "um": "um", "µm": "um",
              "μm": "um", "\\u00b5m": "um", "micrometer": "um", "micrometre": "um", "micron": "um", "microns": "um",
              "nm": "nm", "nanometer": "nm", "nanometre": "nm", "nanometers": "nm", "a": "A", "å": "A",
              "angstrom": "A"}
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


def unit_named(name) -> str | None:
    """The world unit (:data:`UNIT_METRES`) an input's unit ``name`` is (:data:`UNIT_NAMES`, any case), or None."""
    return UNIT_NAMES.get(str(name).strip().lower())


def check_unit(unit):
    """``unit`` (None: not a known length) as one of :data:`UNIT_METRES`; one InputError otherwise."""
    if unit is not None and not (isinstance(unit, str) and unit in UNIT_METRES):
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


def check_scale_bar(scale_bar):
    """``scale_bar`` (None or False: none; True: :func:`nice_length`; a length in world units) as None, True or a
    positive float; one InputError otherwise."""
    if scale_bar is None or scale_bar is False or scale_bar is True:
        return scale_bar or None
    if not (isinstance(scale_bar, (int, float, np.integer, np.floating)) and np.isfinite(scale_bar) and scale_bar > 0):
        raise InputError(f"scale_bar={scale_bar!r} must be True (a length about a fifth of the width) or a positive "
                         f"length in world units, e.g. 10", cli=f"--scale-bar {scale_bar} must be a positive length "
                                                                f"in world units, e.g. 10, or left out (a fifth of the "
                                                                f"width)")
    return float(scale_bar)


def check_orthographic(camera: dict):
    """Refuse a scale bar on the picture of ``camera`` (a ``to_dict()``) where it is not orthographic: a perspective
    view or a cone beam has no single scale across the picture."""
    if camera.get("kind") != "camera" or camera.get("perspective"):
        raise InputError("a scale bar needs an orthographic view, of one scale across the picture: leave out "
                         "perspective=True, or the scale bar", cli="--scale-bar needs an orthographic view, of one "
                                                                   "scale across the picture: leave out --perspective, "
                                                                   "or --scale-bar")


def nice_length(width: float) -> float:
    """The longest 1, 2 or 5 times a power of ten that is at most a fifth of ``width`` (a scale bar's default)."""
    fifth = width / 5.0
    power = 10.0 ** np.floor(np.log10(fifth))
    return max(m * power for m in (1.0, 2.0, 5.0, 10.0) if m * power <= fifth * (1 + 1e-12))


#: the units a scale bar's label is written in, with their length in metres
_LABEL_UNITS = (("m", 1.0), ("mm", 1e-3), ("µm", 1e-6), ("nm", 1e-9))


def length_label(length: float, unit, digits=6) -> str:
    """``length`` world units as a scale bar's label: in ``unit`` where it reads 1 to 999, else in the metre, mm, µm or
    nm that does ("500 µm" for 0.5 mm; ångströms always in nm); with ``unit`` None the number and "units"; ``digits``
    significant."""
    if unit is None:
        return f"{length:.{digits}g} unit{'' if length == 1 else 's'}"
    name, metres = unit.replace("um", "µm"), length * UNIT_METRES[unit]
    if not 1 <= length < 1000 or unit == "A":  # the label's font has no Å: ångströms in nanometres
        name, per = next(((n, m) for n, m in _LABEL_UNITS if metres >= m * (1 - 1e-9)), _LABEL_UNITS[-1])
        length = metres / per
    return f"{length:.{digits}g} {name}"


def draw_scale_bar(picture, pixel: float, unit=None, length=None) -> np.ndarray:
    """``picture`` (as :func:`write_png` takes it) with a scale bar of ``length`` world units (True or None: the
    :func:`nice_length` of the picture's width) burnt into its bottom-right corner: a white bar exactly
    ``round(length / pixel)`` pixels long under its label (:func:`length_label`), both outlined in black so that they
    read on any background, opaque in a transparent picture; ``pixel`` the world width of a pixel (an orthographic
    view's).  One InputError where the bar is under 2 pixels or it and its label do not fit."""
    from PIL import Image, ImageDraw

    height, width = picture.shape[:2]
    chosen = length is None or length is True  # the default: no other length to suggest
    length = nice_length(width * pixel) if chosen else length
    text = length_label(length, unit)
    font, font_size, rim, margin = _annotation_font(height, width)
    thick = max(2, round(font_size / 4))
    drawn = text.replace("µ", "u")  # Pillow's bundled font has no µ (it draws a box): "um", as plain text writes it
    left, top, right, bottom = font.getbbox(drawn, stroke_width=rim)
    room = width - 2 * (margin + rim)
    if room < 2:
        raise InputError(f"the {width}x{height}-pixel picture has no room for a scale bar (it needs "
                         f"{width - room + 2} pixels across): give a larger picture size, or no scale bar")
    pixels = length / pixel
    bar = round(pixels) if pixels <= room else room + 1  # no round() of 1e308 / 0.1, infinity
    what = f"a scale bar of {text} ({pixels:.3g} pixels at {length_label(pixel, unit, 3)} a pixel)"
    if bar < 2 or bar > room:
        why = "is under 2 pixels" if bar < 2 else f"is longer than the {room} pixels the {width}-pixel-wide picture " \
                                                  f"has for it"
        if chosen:
            raise InputError(f"{what} {why}: give a larger picture size, or no scale bar")
        raise InputError(f"{what} {why}: give a length from {length_label(2 * pixel, unit, 3)} to "
                         f"{length_label(room * pixel, unit, 3)}, or no length (a fifth of the width: "
                         f"{length_label(nice_length(width * pixel), unit)})")
    x1, y1 = width - margin - rim, height - margin - rim  # the white bar's right end and bottom, exclusive
    gap = max(2, rim + 1)
    if right - left > width - 2 * margin or (bottom - top) + gap + thick + 2 * rim > height - 2 * margin:
        raise InputError(f"{what}: its label ({right - left}x{bottom - top} pixels) does not fit the {width}x{height} "
                         f"picture: give a larger picture size")
    cover, white = Image.new("L", (width, height)), Image.new("L", (width, height))  # all that is drawn; its white
    box = (x1 - bar, y1 - thick, x1 - 1, y1 - 1)
    ImageDraw.Draw(cover).rectangle((box[0] - rim, box[1] - rim, box[2] + rim, box[3] + rim), fill=255)
    ImageDraw.Draw(white).rectangle(box, fill=255)
    x = min((2 * x1 - bar - (right - left)) / 2, width - margin - right + left)  # centred on the bar, within the margin
    at = (x - left, y1 - thick - rim - gap - bottom)
    ImageDraw.Draw(cover).text(at, drawn, font=font, fill=255, stroke_width=rim, stroke_fill=255)
    ImageDraw.Draw(white).text(at, drawn, font=font, fill=255)
    return _drawn(picture, cover, white)


def _annotation_font(height, width) -> tuple:
    """``(font, size, rim, margin)`` of the annotations drawn into a ``height`` x ``width`` picture (a scale bar's, a
    colour bar's): Pillow's bundled font at a 24th of the picture's shorter side (12 pixels at least), the black rim
    that outlines what is drawn and the margin kept from the picture's edges, in pixels."""
    from PIL import ImageFont

    size = max(12, round(min(height, width) / 24))
    return ImageFont.load_default(size=size), size, max(1, round(size / 9)), max(4, round(size / 2))


def _drawn(picture, cover, white) -> np.ndarray:
    """``picture`` under the overlay of masks ``cover`` (all that is drawn) and ``white`` (its white), Pillow "L"
    images of its size: the part they cover is composited (:func:`_over`), the rest of the picture copied."""
    box = cover.getbbox()
    corner, out = np.s_[box[1]:box[3], box[0]:box[2]], picture.copy()
    out[corner] = _over(picture[corner], *(np.asarray(m.crop(box), np.float64) / 255 for m in (cover, white)))
    return out


EDGES = ("left", "right", "top", "bottom")  #: the picture's edges that :func:`draw_edge_labels` writes at


def check_edge_labels(labels) -> dict:
    """``labels`` as :func:`draw_edge_labels` takes them: a dict of some :data:`EDGES` to short strings; one
    InputError naming what is wrong otherwise."""
    if not isinstance(labels, dict) or not set(labels) <= set(EDGES) or \
            not all(isinstance(t, str) and 0 < len(t) <= 8 for t in labels.values()):
        raise InputError(f"edge_labels={labels!r} must be a dict of some of {', '.join(EDGES)} to short strings "
                         f"(1 to 8 characters), e.g. dict(left='R', right='L', top='S', bottom='I')")
    return labels


def draw_edge_labels(picture, labels: dict) -> np.ndarray:
    """``picture`` (as :func:`write_png` takes it) with ``labels`` burnt in at the middle of its edges (keys ``left``,
    ``right``, ``top``, ``bottom``: which way the view faces there, the viewer's orientation letters,
    ``clwave.view.orientation.edges``), white outlined in black as the page draws them, in the scale bar's font."""
    from PIL import Image, ImageDraw

    height, width = picture.shape[:2]
    font, font_size, rim, _ = _annotation_font(height, width)
    margin = max(2, round(font_size / 4))  # nearer the edges than the bars: the page's letters
    cover, white = Image.new("L", (width, height)), Image.new("L", (width, height))
    for edge, text in labels.items():
        drawn = text.replace("−", "-")  # the axes' minus: Pillow's bundled font has no U+2212
        left, top, right, bottom = font.getbbox(drawn, stroke_width=rim)
        x = dict(left=margin, right=width - margin - (right - left)).get(edge, (width - right + left) / 2)
        y = dict(top=margin, bottom=height - margin - (bottom - top)).get(edge, (height - bottom + top) / 2)
        ImageDraw.Draw(cover).text((x - left, y - top), drawn, font=font, fill=255, stroke_width=rim, stroke_fill=255)
        ImageDraw.Draw(white).text((x - left, y - top), drawn, font=font, fill=255)
    return _over(picture, *(np.asarray(m, np.float64) / 255 for m in (cover, white)))


def draw_colour_bar(picture, shade, window) -> np.ndarray:
    """``picture`` (an X-ray's, grey (H, W) or colour (H, W, 3)) with a vertical colour bar burnt into its top-right
    corner, two fifths of its height long: its rows ``shade``'s pixel values (of fractions of the window, 1 its high
    end at the top, 0 its low end at the bottom; (L,) grey or (L, 3)), outlined in black; left of it the window's
    ``(lo, hi)`` at its ends and 0 where it lies between them (clear of them), white outlined in black as the scale
    bar's label (:func:`draw_scale_bar`, bottom-right: the two never meet).  One InputError where they do not fit."""
    from PIL import Image, ImageDraw

    height, width = picture.shape[:2]
    font, font_size, rim, margin = _annotation_font(height, width)
    lo, hi = window
    length = round(0.4 * height)
    ticks = [(0, f"{hi:.3g}"), (length - 1, f"{lo:.3g}")]
    boxes = [font.getbbox(text, stroke_width=rim) for _, text in ticks]
    tall = max(b[3] - b[1] for b in boxes)
    if lo < 0 < hi:
        row = round((length - 1) * hi / (hi - lo))
        if tall < row < length - 1 - tall:  # else its label would cover an end's
            ticks.append((row, "0"))
            boxes.append(font.getbbox("0", stroke_width=rim))
    gap = max(2, rim + 1)
    x1 = width - margin - rim  # the bar's right end, exclusive
    x0, y0 = x1 - font_size, margin + rim + tall // 2 + 1
    wide = max(b[2] - b[0] for b in boxes)
    if length < 16 or x0 - rim - gap - wide < margin or y0 + length + tall // 2 + rim > height - margin:
        raise InputError(f"the {width}x{height}-pixel picture has no room for a colour bar and its labels "
                         f"({wide} pixels wide): give a larger picture size, or no colour bar")
    cover, white = Image.new("L", (width, height)), Image.new("L", (width, height))
    ImageDraw.Draw(cover).rectangle((x0 - rim, y0 - rim, x1 - 1 + rim, y0 + length - 1 + rim), fill=255)
    for (row, text), (left, top, right, bottom) in zip(ticks, boxes):  # right-aligned, centred on their rows
        at = (x0 - rim - gap - right, y0 + row - (top + bottom) / 2)
        ImageDraw.Draw(cover).text(at, text, font=font, fill=255, stroke_width=rim, stroke_fill=255)
        ImageDraw.Draw(white).text(at, text, font=font, fill=255)
    out = _drawn(picture, cover, white)
    out[y0:y0 + length, x0:x1] = np.asarray(shade(np.linspace(1.0, 0.0, length)))[:, None]
    return out


def _over(picture, cover, white) -> np.ndarray:
    """``picture`` under a white-on-black overlay of coverage ``cover`` (its white part ``white``), straight alpha."""
    top = float(np.iinfo(picture.dtype).max)
    values = picture.astype(np.float64) / top
    grey = values.ndim == 2
    values = values[..., None] if grey else values
    colour, alpha = (values[..., :3], values[..., 3:]) if values.shape[-1] == 4 else (values, None)
    cover, white = cover[..., None], white[..., None]
    if alpha is None:
        colour = colour * (1 - cover) + white
    else:  # "over" in straight alpha: the overlay opaque where it covers the pixel
        under = alpha * (1 - cover)
        alpha = cover + under
        colour = np.divide(white + colour * under, alpha, out=np.zeros_like(colour), where=alpha > 0)
        colour = np.concatenate([colour, alpha], axis=-1)
    out = np.round(top * np.clip(colour, 0, 1)).astype(picture.dtype)
    return out[..., 0] if grey else out


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


#: the seconds a GIF frame may be shown: stored in hundredths of a second, 16 bits (655.35 s at most); browsers show
#: a frame of less than 0.02 s for 0.1 s
GIF_FRAME_SECONDS = (0.02, 655.35)


def check_frame_time(seconds) -> float:
    """A GIF frame's seconds (``frame_time=``, ``--frame-time``) within :data:`GIF_FRAME_SECONDS` (NaN fails), as a
    float; one InputError otherwise."""
    lo, hi = GIF_FRAME_SECONDS
    number = isinstance(seconds, (int, float, np.integer, np.floating)) and not isinstance(seconds, (bool, np.bool_))
    if not (number and lo <= seconds <= hi):
        why = (f"must be the seconds each frame is shown, from {lo:g} (browsers show a shorter frame for 0.1 s) to "
               f"{hi:g} (a GIF's longest), e.g. 0.1")
        shown = f"{seconds:g}" if number else repr(seconds)
        raise InputError(f"frame_time={seconds!r} {why}", cli=f"--frame-time {shown} {why}")
    return float(seconds)


def write_gif(path, pictures, seconds_per_frame, force) -> Path:
    """A looping GIF of ``pictures`` at ``path`` (:func:`gif_to`)."""
    return write_atomic(path, lambda fh: gif_to(fh, pictures, seconds_per_frame), force)


def gif_to(fh, pictures, seconds_per_frame):
    """Write a looping GIF of ``pictures`` to the binary file ``fh``, each shown ``seconds_per_frame`` (to the
    hundredth, the format's unit)."""
    from PIL import Image

    frames = np.stack(pictures)  # every frame RGB: grey frames were written in modes some readers cannot read back
    frames = np.repeat(frames[..., None], 3, axis=-1) if frames.ndim == 3 else frames
    # whole milliseconds, which Pillow truncates to hundredths: int(1000 * 2.01) is 2009, stored as 2 s
    duration = 10 * round(100 * seconds_per_frame)
    # by Pillow itself: imageio's writer, interrupted, wrote to the closed file from its __del__
    first, *rest = (Image.fromarray(frame) for frame in frames)
    first.save(fh, format="GIF", save_all=True, append_images=rest, duration=duration, loop=0)
