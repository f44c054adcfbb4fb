"""RenderResult: the image a renderer returns, its figures, and how it is written.

X-ray images (line integrals) are written to PNG through a linear window
(``"auto"`` = the 0.5 and 99.5 percentiles, or ``(lo, hi)``); emission-absorption
images (premultiplied RGBA) are composited over a background colour, or kept
transparent (straight alpha, as PNG holds it), and encoded as sRGB; 8 or 16 bits a
sample.  ``.tif`` and ``.npy`` keep the float32 image as rendered (:mod:`.images`).
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from .files import check_suffix, write_atomic
from .images import (PNG_SUFFIXES, TIFF_SUFFIXES, UNIT_METRES, check_bit_depth, check_orthographic, check_scale_bar,
                     check_edge_labels, check_unit, draw_colour_bar, draw_edge_labels, draw_scale_bar, pixel_size,
                     write_png, write_tiff)
from ..model.tf_passes import AUTO_PERCENTILES
from ..model.tf_checks import check_window

#: the longest side of the picture a notebook shows of a result (:meth:`RenderResult._repr_png_`): a larger image is
#: reduced by a whole factor, so that a notebook does not carry a full-size PNG in its file
REPR_PNG_SIDE = 512


@dataclass(repr=False)  # not the whole array: a text front-end or nbconvert shows the repr
class RenderResult:
    """``image`` float32 (H, W, C); ``meta``: method, device, counts, timings in seconds, and the view: ``camera``
    (the camera given, its ``to_dict()``), ``pixel`` (world width of a pixel at the target; docs/coordinates.md
    §3) and ``unit`` (the model's world unit, "A", "nm", ... ; None where the input gave none)."""

    image: np.ndarray
    meta: dict = field(default_factory=dict)

    @property
    def is_xray(self) -> bool:
        return self.meta.get("mode", "xray") == "xray"

    def to_uint8(self, window="auto", background=None) -> np.ndarray:
        """8-bit :meth:`picture`."""
        return self.picture(window, background)

    def picture(self, window="auto", background=None, bit_depth=8, scale_bar=None, unit=None,
                colour_map=None, colour_bar=False, edge_labels=None) -> np.ndarray:
        """8- or 16-bit (H, W) grey or (H, W, 3) colour picture of the image: an X-ray of one channel grey, of two
        magenta (channel 0) and green (1), of three or four its first three as RGB; one window for all.  A shaded
        image is composited over ``background`` (linear RGB in 0..1, default black) before its sRGB encoding, or
        with ``background="transparent"`` (H, W, 4): its colour unpremultiplied (clipped to 1 where light was
        added), sRGB-encoded, and its alpha.  ``scale_bar`` (True, or a length in ``unit``) burns in a scale bar
        (:func:`~clwave.io.images.draw_scale_bar`): an orthographic view's only.  ``unit`` (:meth:`in_unit`): the
        bar's unit, converted from the result's own (``meta["unit"]``, the default); where that is None, the
        world unit it declares.  ``colour_map``: a one-channel X-ray's grey levels in the colours of a map
        (:data:`clwave.view.colours.NAMES`, the viewer's: "grey_r" shows dark bright, at 8 or 16 bits; "viridis",
        "magma_r", ... 8 bits only).  ``colour_bar``: a one-channel X-ray's colour bar, its colours from the window's
        low end to its high end, labelled with both and 0 between them (:func:`~clwave.io.images.draw_colour_bar`).
        ``edge_labels``: a dict of the text at the middle of the picture's ``left``, ``right``, ``top`` and ``bottom``
        edges (:func:`~clwave.io.images.draw_edge_labels`; the viewer's orientation letters, which its saved image
        holds), burnt in after the bars."""
        from ..view.colours import apply, check_colour_map

        colour_map = check_colour_map(colour_map)
        if check_colour_bar(colour_bar):
            check_colour_barred(self.is_xray, self.image.shape[-1])
        if colour_map is not None:
            check_colour_mapped(colour_map, self.is_xray, self.image.shape[-1], bit_depth)
        if (scale_bar := check_scale_bar(scale_bar)) is not None:
            check_orthographic(self.meta.get("camera") or {})
        if self.is_xray and background is not None:
            raise InputError(f"background={background!r} is for a shaded image; an X-ray picture has no background "
                             f"(its line integrals are shown through window=): leave it out")
        top = float((1 << check_bit_depth(bit_depth)) - 1)
        background = check_background((0.0, 0.0, 0.0) if background is None else background)
        # 16 bits in float64: float32's rounding (6e-8 of the value) would move levels near their ties
        wide = np.float32 if top < 256 else np.float64
        if self.is_xray:
            picture = self._picture().astype(wide, copy=False)
            lo, hi = resolve_window(picture, window, colour_map)
            with np.errstate(over="ignore", under="ignore"):  # a narrow window's quotients past float32: clipped to 1
                ends = np.array([lo, hi, hi - lo], wide)
                if not (np.all(np.isfinite(ends)) and ends[2] > 0):  # else NaN levels, written as 0 with a warning
                    why = (f"is beyond {np.dtype(wide).name}, in which the {int(top).bit_length()}-bit picture is "
                           f"made (its ends and its width must be finite there, the width above 0): choose a window "
                           f"nearer the image's values")
                    raise InputError(f"window=({lo:g}, {hi:g}) {why}", cli=f"--window {lo:g},{hi:g} {why}")
                scaled = np.clip((picture - lo) / (hi - lo), 0.0, 1.0)
            if self.image.shape[-1] == 2:  # a pair colour-blind eyes tell apart too
                scaled = scaled[..., [0, 1, 0]]
        else:
            image = self.image.astype(wide, copy=False)
            rgb, alpha = image[..., :3], np.clip(image[..., 3:4], 0.0, 1.0)
            if background == "transparent":  # PNG's alpha is straight: the colour is the premultiplied over alpha
                rgb = np.divide(rgb, alpha, out=np.zeros_like(rgb), where=alpha > 0)
            else:
                rgb = rgb + (1.0 - alpha) * np.asarray(background, np.float32)
            scaled = np.clip(rgb, 0.0, 1.0)
            scaled = np.where(scaled <= 0.0031308, 12.92 * scaled, 1.055 * scaled ** (1 / 2.4) - 0.055)
            if background == "transparent":
                scaled = np.concatenate([scaled, alpha], axis=-1)
        picture = np.round(top * scaled).astype(np.uint8 if top < 256 else np.uint16)
        if colour_map is not None:
            picture = apply(picture, colour_map, int(top))
        if colour_bar:
            picture = draw_colour_bar(picture, lambda f: apply(np.round(top * f).astype(picture.dtype),
                                                               colour_map or "grey", int(top)), (lo, hi))
        if scale_bar is not None:
            factor, unit = self.in_unit(unit)
            picture = draw_scale_bar(picture, self.meta["pixel"] * factor, unit, scale_bar)
        return picture if edge_labels is None else draw_edge_labels(picture, check_edge_labels(edge_labels))

    def in_unit(self, unit=None) -> tuple:
        """``(factor, unit)``: the length unit a picture's scale bar and pixel size are written in (``unit``, or
        ``meta["unit"]`` where it is None) and the factor that converts world units into it; where ``meta`` has no
        unit, a given ``unit`` declares the world unit (factor 1).  One InputError for an unknown ``unit``."""
        unit, own = check_unit(unit), self.meta.get("unit")
        if unit is None or own is None or unit == own:
            return 1.0, unit or own
        return UNIT_METRES[own] / UNIT_METRES[unit], unit

    def _pixel_size(self, factor) -> tuple | None:
        """:func:`~clwave.io.images.pixel_size` times ``factor`` (:meth:`in_unit`'s)."""
        size = pixel_size(self.meta)
        return None if size is None else tuple(factor * s for s in size)

    @property
    def seconds(self) -> float | None:
        """The render's time (a ray trace's without its set-up, a splat's in all); None where ``meta`` has none."""
        seconds = self.meta.get("render_seconds", self.meta.get("seconds"))
        return seconds["total"] if isinstance(seconds, dict) else seconds

    def __repr__(self) -> str:
        seconds = "" if self.seconds is None else f", {self.seconds:.3g} s"
        return f"RenderResult({summary(self.image, self.meta)}{seconds})"

    def _repr_png_(self) -> bytes | None:
        """The 8-bit PNG of :meth:`picture` with its defaults, as Jupyter shows a result: :func:`reduced` for a
        notebook; None, the text, for an image with non-finite values, which is never a picture."""
        if not np.all(np.isfinite(self.image)):
            return None
        buffer = io.BytesIO()
        write_png(buffer, reduced(self.picture()))
        return buffer.getvalue()

    def display_window(self, window="auto", colour_map=None):
        """The ``(lo, hi)`` an X-ray picture (:meth:`picture`) in ``colour_map`` is shown through for ``window``
        ("auto" resolved from this image); None for a shaded image, which has no window."""
        return resolve_window(self._picture(), window, colour_map) if self.is_xray else None

    def _picture(self) -> np.ndarray:
        """The X-ray values shown: one channel's, or the first three's."""
        return self.image[..., :3] if self.image.shape[-1] > 1 else self.image[..., 0]

    def save(self, path, *, window="auto", background=None, bit_depth=None, unit=None, scale_bar=None,
             colour_map=None, colour_bar=False, edge_labels=None, overwrite=False) -> Path:
        """Write ``.png`` (windowed, or composited over ``background`` or transparent: :meth:`picture`, of
        ``bit_depth`` 8 or 16 bits a sample), ``.tif``/``.tiff`` (float32, as rendered; a shaded image's alpha
        associated, premultiplied), ``.npy`` (raw float32) or ``.json`` (meta).  ``unit`` (:meth:`in_unit`): the
        unit ("nm", :data:`~clwave.io.images.UNIT_METRES`) the pixel size and scale bar are written in, converted
        from the result's own world unit (``meta["unit"]``, the default); where that is None, the world unit it
        declares.  The size of a pixel (:func:`~clwave.io.images.pixel_size`) goes into a PNG's pHYs where its unit
        is known, into a TIFF's resolution always (per world unit where it is not).  ``scale_bar``: a ``.png``'s
        scale bar, ``colour_map`` an X-ray's colours, ``colour_bar`` its colour bar and ``edge_labels`` the words at
        its edges (:meth:`picture`).

        An image with non-finite pixels is refused (nothing is written): it is never a picture."""
        path = check_suffix(path, PNG_SUFFIXES + TIFF_SUFFIXES + (".npy", ".json"))
        suffix = path.suffix.lower()
        bits, (factor, known) = check_bit_depth(bit_depth), self.in_unit(unit)
        given = [f"{name}=" for name, value in (("window", None if isinstance(window, str) and window == "auto" else
                                                 window), ("background", background), ("bit_depth", bit_depth),
                                                ("scale_bar", check_scale_bar(scale_bar)), ("colour_map", colour_map),
                                                ("colour_bar", check_colour_bar(colour_bar) or None),
                                                ("edge_labels", edge_labels))
                 if value is not None]
        if given and suffix not in PNG_SUFFIXES:
            raise InputError(f"{' and '.join(given)} {'set' if len(given) > 1 else 'sets'} a .png's picture; {path} "
                             f"holds the image's {'figures' if suffix == '.json' else 'values'}: leave "
                             f"{'them' if len(given) > 1 else 'it'} out")
        bad = int(np.size(self.image) - np.count_nonzero(np.isfinite(self.image)))
        if bad and suffix != ".json":
            raise InputError(f"the image has {bad} non-finite value(s) (NaN/Inf), so {path} was not written; "
                             f"the input holds values too large for float32, or the view is degenerate")
        if suffix in PNG_SUFFIXES:
            data = self.picture(window, background, bits, scale_bar, unit, colour_map, colour_bar, edge_labels)
            return write_atomic(path, lambda fh: write_png(fh, data, self._pixel_size(factor), known), overwrite)
        if suffix in TIFF_SUFFIXES:
            image = self.image[..., 0] if self.image.shape[-1] == 1 else self.image
            return write_atomic(path, lambda fh: write_tiff(fh, image, self._pixel_size(factor), known,
                                                            alpha=not self.is_xray), overwrite)
        if suffix == ".npy":
            return write_atomic(path, lambda fh: np.save(fh, self.image), overwrite)
        text = json.dumps(self.meta, indent=2, default=_jsonable).encode()
        return write_atomic(path, lambda fh: fh.write(text), overwrite)


def check_colour_mapped(name, xray, channels, bit_depth):
    """Refuse (one line) the colour map ``name`` for a picture it does not colour: a shaded image (not ``xray``: its
    transfer function's colours), an X-ray of several ``channels`` (shown in their own), a map of colours at 16 bits
    (its table has 256)."""
    if not xray or channels > 1:
        what = "a shaded image has its transfer function's colours" if not xray else \
            f"this X-ray has {channels} channels, shown in colours of their own"
        raise InputError(f"colour_map={name!r} colours a one-channel X-ray's grey levels; {what}: leave it out",
                         cli=f"--colour-map {name} colours a one-channel X-ray's grey levels; {what}: leave it out")
    if not name.startswith("grey") and bit_depth == 16:
        raise InputError(f"colour_map={name!r} has 256 colours, for an 8-bit picture: leave out bit_depth=16, or "
                         f"use grey or grey_r", cli=f"--colour-map {name} has 256 colours, for an 8-bit picture: "
                                                    f"leave out --bit-depth 16, or use grey or grey_r")


def check_colour_bar(colour_bar) -> bool:
    """``colour_bar`` (None, False or True) as a bool; one InputError otherwise."""
    if colour_bar is None or isinstance(colour_bar, (bool, np.bool_)):
        return bool(colour_bar)
    raise InputError(f"colour_bar={colour_bar!r} must be True (a colour bar) or False")


def check_colour_barred(xray, channels):
    """Refuse (one line) a colour bar where no one scale of values gives the picture's colours: a shaded image (not
    ``xray``: its transfer function's colours and opacity, composited), an X-ray of several ``channels``."""
    if not xray:
        what = ("a shaded image's colours are its transfer function's, composited along each ray, with no one "
                "window of values: render an X-ray for a colour bar (splatting, or ray tracing with {xray}), or show "
                "the transfer function beside the picture")
        raise InputError(f"colour_bar=True {what.format(xray='absorption=False')}",
                         cli=f"--colour-bar {what.format(xray='--xray')}")
    if channels > 1:
        what = f"this X-ray has {channels} channels, shown in colours of their own, not one scale"
        raise InputError(f"colour_bar=True keys a one-channel X-ray's values; {what}: leave it out",
                         cli=f"--colour-bar keys a one-channel X-ray's values; {what}: leave it out")


def summary(image, meta) -> str:
    """A result's image in a few words: its method and mode, shape, type and range (a shaded image's alpha's)."""
    shaded = meta.get("mode", "xray") != "xray"
    values = image[..., 3] if shaded else image
    finite = values[np.isfinite(values)]
    span = f"{float(finite.min()):.3g} .. {float(finite.max()):.3g}" if finite.size else "no finite value"
    bad = "" if finite.size == values.size else f", {values.size - finite.size} non-finite"
    method = f"{meta['method']} " if meta.get("method") else ""
    return (f"{method}{'shaded RGBA' if shaded else 'X-ray'}, {'x'.join(map(str, image.shape))} "
            f"{image.dtype}, {'alpha' if shaded else 'values'} {span}{bad}")


def reduced(picture: np.ndarray) -> np.ndarray:
    """``picture`` (H, W[, C]) reduced by the least whole factor that brings its longest side to at most
    :data:`REPR_PNG_SIDE` pixels (Pillow's box average), as a notebook shows it."""
    from PIL import Image

    image = Image.fromarray(picture)
    return np.asarray(image.reduce(-(-max(image.size) // REPR_PNG_SIDE)))


def check_background(background) -> tuple | str:
    """A background colour (R, G, B), linear light each in 0..1, as floats, or "transparent"; one InputError (in the
    command line's words too) otherwise."""
    if isinstance(background, str) and background == "transparent":
        return background
    try:
        colour = tuple(float(c) for c in background)
    except (TypeError, ValueError):
        colour = ()
    if isinstance(background, (str, bytes)) or len(colour) != 3 or not all(0 <= c <= 1 for c in colour):
        spec = ",".join(f"{c:g}" for c in colour) if colour else background
        raise InputError(f"background={background!r} must be a colour (R, G, B) with each in 0..1, e.g. (1, 1, 1) "
                         f"for white, or 'transparent'", cli=f"--background {spec} must be a colour R,G,B with each in "
                                                            f"0..1, e.g. 1,1,1 for white, or transparent")
    return colour


def resolve_window(values, window="auto", colour_map=None) -> tuple:
    """``(lo, hi)`` of a display window: "auto" (percentiles of the finite values; centred on 0 for a diverging
    ``colour_map``, :func:`~clwave.view.colours.centred`) or given."""
    from ..view.colours import centred

    checked = check_window(window)
    if checked is None:
        raise InputError("a display window must be 'auto' or (lo, hi)")
    if checked != "auto":
        return checked
    finite = np.asarray(values)[np.isfinite(values)]
    lo, hi = (float(p) for p in np.percentile(finite, AUTO_PERCENTILES)) if finite.size else (0.0, 1.0)
    if hi <= lo:
        hi = lo + 1.0  # a flat image (a view that misses the volume) shows black
    return centred((lo, hi), colour_map)


def _jsonable(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return str(obj)
