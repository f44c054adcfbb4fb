"""The viewer's WebSocket messages (docs/viewer.md §3): what a page may send, checked field by field.

A page sends only JSON text messages ``{"type": "view", ...}`` holding the whole state of its view; the
server answers with one JSON text ``hello`` and then binary frames: a 4-byte big-endian length, that many
bytes of JSON figures, then the encoded picture.  Nothing a page sends names a file or a command: a message
is a view or it is refused, and a refused message closes its connection (:class:`Refused`).
"""

from __future__ import annotations

import json
import struct
import time

from ..model.clip import MAX_PLANES
from . import colours
from .frames import ViewState

#: the largest message a page may send (a view is about 250 bytes; with 32 transfer-function points, at most 2.3 KB)
MAX_MESSAGE = 4096
#: messages per second a page may send on average, and in a burst (the page sends at most one per
#: animation frame, 60 a second)
RATE, BURST = 120.0, 240
ZOOM = (0.1, 50.0)
#: a perspective view's vertical field of view, degrees (the page's slider's span)
FOV = (5.0, 120.0)
#: the sides of an image the page may ask for (docs/viewer.md §5: saved, or its command's): at most 4096 pixels
EXPORT_SIZE = (8, 4096)
#: close codes (RFC 6455 §7.4.1): policy violation, message too big
POLICY, TOO_BIG = 1008, 1009
#: a close frame's reason: at most 123 bytes of UTF-8 (RFC 6455 §5.5), or the page's browser fails the connection
REASON_BYTES = 120


class Refused(Exception):
    """A message that closes its connection; ``str()`` is the logged reason, ``code`` the close code."""

    def __init__(self, reason, code=POLICY):
        super().__init__(reason)
        self.code = code


def _number(msg, name, lo, hi) -> float:
    return _value(msg.get(name), name, lo, hi)


def _value(value, name, lo, hi) -> float:
    # compared, not converted: NaN fails the comparison, +-Infinity lie outside every span, and a whole number of 400
    # digits (on which float() and math.isfinite raise OverflowError) is compared exactly
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not lo <= value <= hi:
        raise Refused(f"{name}={value!r} must be a number from {lo:g} to {hi:g}")
    return float(value)


def _flag(msg, name) -> bool:
    value = msg.get(name)
    if not isinstance(value, bool):
        raise Refused(f"{name}={value!r} must be true or false")
    return value


FIELDS = {"type", "seq", "azimuth", "elevation", "zoom", "mode", "detail", "window", "moving", "background",
          "shading", "tf", "colour_map", "fov", "scale_bar", "edge_labels", "clip"}
#: a transfer function from the page's editor: a preset, its window's centre moved by this many of its widths (the
#: page's slider keeps the centre within the input's range, many widths of a narrow window), its width times this, its
#: opacity times this (clwave.view.shaded.ShadedSource.transfer_function)
TF_RANGES = dict(centre=(-1e6, 1e6), width=(0.02, 50.0), opacity=(1e-3, 1e3))
#: or its own points: at most this many rows (value, r, g, b, opacity), each number within its span (a value in data
#: units, an opacity per unit length: the presets' are at most 0.5)
TF_POINTS = 32
POINT_RANGES = dict(value=(-1e30, 1e30), r=(0.0, 1.0), g=(0.0, 1.0), b=(0.0, 1.0), opacity=(0.0, 1e3))


def _tf(value):
    """``(preset, centre, width, opacity)`` of a page's ``tf`` field (preset None: the starting transfer function,
    the one the server was given, the model's own or grey), a TransferFunction of its ``points`` (in the
    input's units), or None (the starting function as it is)."""
    from ..model.transfer import TransferFunction

    if value is None:
        return None
    if isinstance(value, dict) and set(value) == {"points"}:
        return _points(value["points"])
    if not isinstance(value, dict) or set(value) != {"preset", *TF_RANGES}:
        raise Refused(f"tf must be null, {{\"points\"}} or {{\"preset\", {', '.join(map(repr, TF_RANGES))}}}")
    if value["preset"] is not None and value["preset"] not in TransferFunction.PRESETS:
        raise Refused(f"tf preset={value['preset']!r} must be null (the starting one) or one of "
                      f"{', '.join(TransferFunction.PRESETS)}")
    return (value["preset"], *(_number(value, name, *span) for name, span in TF_RANGES.items()))


def _points(rows):
    """The TransferFunction of the editor's points ``[[value, r, g, b, opacity], ...]``, values in the input's
    units (its own checks: values strictly increasing), or :class:`Refused`."""
    from ..errors import InputError
    from ..model.transfer import TransferFunction

    if not isinstance(rows, list) or not 2 <= len(rows) <= TF_POINTS or \
            not all(isinstance(row, list) and len(row) == len(POINT_RANGES) for row in rows):
        raise Refused(f"tf points must be 2 to {TF_POINTS} rows [value, r, g, b, opacity]")
    points = [[_value(x, f"tf point {i} {name}", *span) for x, (name, span) in zip(row, POINT_RANGES.items())]
              for i, row in enumerate(rows)]
    try:
        tf = TransferFunction(points, name="edited")
    except InputError as exc:
        raise Refused(f"tf points: {exc}") from None
    # the kernel's table maps the points' span to [0, 1] in float32 (raytrace.classified.tf_table): its scale, one over
    # the span, stays finite (its shift, the first value over the span, does then: distinct doubles within 1e30)
    span = points[-1][0] - points[0][0]
    if not span >= 1e-30:
        raise Refused(f"tf points span {span:g}: at least 1e-30, for the renderer's float32 table")
    return tf


#: a clip's corners and planes' points and normals: world units, within this span
CLIP_SPAN = (-1e30, 1e30)


def _clip(value):
    """``(box, planes)`` of a page's ``clip`` field, in world units (box: 6 numbers x0, y0, z0, x1, y1, z1, or None;
    planes: rows px, py, pz, nx, ny, nz), or None (no clip).  Only its form is checked here: what it keeps is the
    :class:`~clwave.Clip`'s to say, on the tab's status line (:meth:`ViewState.clipping`)."""
    if value is None:
        return None
    if not isinstance(value, dict) or set(value) != {"box", "planes"} or not isinstance(value["planes"], list) \
            or len(value["planes"]) > MAX_PLANES:
        raise Refused(f'clip must be null or {{"box": null or [x0, y0, z0, x1, y1, z1], "planes": at most {MAX_PLANES} '
                      f'[px, py, pz, nx, ny, nz]}}')
    rows = ([] if value["box"] is None else [("clip box", value["box"])]) + \
        [(f"clip plane {i}", row) for i, row in enumerate(value["planes"])]
    for name, row in rows:
        if not isinstance(row, list) or len(row) != 6:
            raise Refused(f"{name} must be 6 numbers")
    rows = [tuple(_value(x, name, *CLIP_SPAN) for x in row) for name, row in rows]
    return (rows.pop(0) if value["box"] is not None else None), tuple(rows)


def _json(text: str):
    if len(text) > MAX_MESSAGE:
        raise Refused(f"a message of {len(text)} characters is more than {MAX_MESSAGE}", TOO_BIG)
    try:
        return json.loads(text)
    except ValueError:
        raise Refused("a message that is not JSON") from None
    except RecursionError:  # 4 KiB hold 2,000 nested arrays, past the interpreter's recursion limit
        raise Refused("a message nested too deep") from None


def parse_export(text: str, modes) -> tuple:
    """``(ViewState, (H, W))`` of a page's request for its view's command or image, ``{"view": a view message,
    "size": [H, W]}`` (each side :data:`EXPORT_SIZE`), or :class:`Refused` naming what is wrong with it."""
    msg = _json(text)
    if not isinstance(msg, dict) or set(msg) != {"view", "size"}:
        raise Refused('a request that is not {"view": {...}, "size": [H, W]}')
    size, (least, most) = msg["size"], EXPORT_SIZE
    if not isinstance(size, list) or len(size) != 2 or \
            not all(isinstance(n, int) and not isinstance(n, bool) and least <= n <= most for n in size):
        raise Refused(f"size={json.dumps(size)[:40]} must be [H, W], whole numbers of pixels from {least} to {most}")
    return view_of(msg["view"], -1, modes), tuple(size)


def parse_view(text: str, last_seq: int, modes) -> ViewState:
    """The :class:`ViewState` of a page's message, or :class:`Refused` naming what is wrong with it."""
    return view_of(_json(text), last_seq, modes)


def view_of(msg, last_seq: int, modes) -> ViewState:
    """The :class:`ViewState` of a page's view message, decoded, or :class:`Refused`."""
    if not isinstance(msg, dict) or msg.get("type") != "view":
        raise Refused("a message that is not {\"type\": \"view\", ...}")
    unknown = sorted(set(msg) - FIELDS)
    if unknown:
        raise Refused(f"unknown field(s) {', '.join(map(repr, unknown[:5]))}")
    seq = msg.get("seq")
    if isinstance(seq, bool) or not isinstance(seq, int) or not last_seq < seq < 2 ** 53:
        raise Refused(f"seq={seq!r} must be a whole number above the last one ({last_seq})")
    if msg.get("mode") not in modes:
        raise Refused(f"mode={msg.get('mode')!r} must be one of {', '.join(modes)}")
    window = msg.get("window")
    if window is not None:
        if not isinstance(window, list) or len(window) != 2:
            raise Refused(f"window={window!r} must be null (auto) or [lo, hi]")
        window = (_value(window[0], "lo", -1e30, 1e30), _value(window[1], "hi", -1e30, 1e30))
        if not window[0] < window[1]:
            raise Refused(f"window {list(window)} must have lo < hi")
    fov = msg.get("fov")
    fov = None if fov is None else _value(fov, "fov", *FOV)
    colour_map = msg.get("colour_map", "grey")
    if colour_map not in colours.NAMES:
        raise Refused(f"colour_map={colour_map!r} must be one of {', '.join(colours.NAMES)}")
    return ViewState(seq=seq, azimuth=_number(msg, "azimuth", -1e6, 1e6), elevation=_number(msg, "elevation", -90, 90),
                     zoom=_number(msg, "zoom", *ZOOM), mode=msg["mode"], detail=_number(msg, "detail", 1e-6, 1.0),
                     window=window, moving=_flag(msg, "moving"), background=_number(msg, "background", 0.0, 1.0),
                     shading=_flag(msg, "shading"), tf=_tf(msg.get("tf")), colour_map=colour_map, fov=fov,
                     scale_bar="scale_bar" in msg and _flag(msg, "scale_bar"),
                     edge_labels="edge_labels" in msg and _flag(msg, "edge_labels"), clip=_clip(msg.get("clip")))


class RateLimit:
    """A token bucket: :data:`RATE` messages a second on average, :data:`BURST` at once."""

    def __init__(self, rate=RATE, burst=BURST, clock=time.monotonic):
        self.rate, self.burst, self.clock = rate, burst, clock
        self.tokens, self.when = float(burst), clock()

    def take(self):
        now = self.clock()
        self.tokens = min(self.burst, self.tokens + (now - self.when) * self.rate)
        self.when = now
        if self.tokens < 1.0:
            raise Refused(f"more than {self.rate:g} messages a second (a burst of {self.burst})")
        self.tokens -= 1.0


def said(exc: BaseException) -> str:
    """``exc`` in one line for the page: its message where it is clwave's, else an internal error (the server logs
    it)."""
    from ..errors import ClwaveError

    return str(exc) if isinstance(exc, ClwaveError) else f"internal error ({type(exc).__name__}); see the server's log"


def model_id(wv) -> str:
    """A digest of what makes the served model the one it is (its grid, channels, spacing, wavelets, levels, input's
    value range and classification; not its coefficients, a file's prefix's until its rest is read): a page keeps its
    view with it and applies a kept view to a model of the same id only (docs/viewer.md §4)."""
    import hashlib

    figures = [list(wv.shape), wv.channels, list(wv.spacing), wv.levels, sorted({g.wavelet.name for g in wv.groups}),
               wv.value_range, (wv.transfer_function or {}).get("name")]
    return hashlib.sha256(json.dumps(figures, default=float).encode()).hexdigest()[:16]


def close_reason(text: str) -> bytes:
    """``text`` as a close frame's reason: its first :data:`REASON_BYTES` bytes of UTF-8, cut between characters."""
    return text.encode()[:REASON_BYTES].decode(errors="ignore").encode()


def pack_frame(figures: dict, data: bytes, mime: str) -> bytes:
    """A binary frame message: the figures (with the picture's type) as JSON, then the picture."""
    head = json.dumps(dict(figures, mime=mime), separators=(",", ":")).encode()
    return struct.pack(">I", len(head)) + head + data


def unpack_frame(message: bytes) -> tuple:
    """``(figures, picture bytes)`` of a frame message (tests and tools; the page does this in JavaScript)."""
    (n,) = struct.unpack(">I", message[:4])
    return json.loads(message[4: 4 + n]), message[4 + n:]
