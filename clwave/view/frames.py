"""Frame sources of the viewer (docs/viewer.md §2): the pictures of one view, cheapest first.

A source turns a :class:`ViewState` into an iterator of :class:`Frame` s.  While the user drags
(``moving``) it yields one cheap frame; when the view is still it refines the same view and yields each
better frame as it completes, the last one ``final``.  The server advances the iterator one frame at a
time on its render thread and drops it as soon as the view changes, so a stage is the unit of abandoned
work.  This is the seam where level-of-detail frames (a ``refine(camera)`` generator of the ray tracer)
and render-time transfer functions plug in: a source declares what it can act on in ``capabilities``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..errors import InputError, finite_number
from ..io.result import RenderResult, resolve_window
from ..model.camera import Camera
from ..model.clip import Clip
from ..model.transfer import TransferFunction
from ..splat.renderer import SplatRenderer
from . import colours, orientation

#: X-ray frames while dragging aim at this many seconds of rendering: the coefficient prefix adapts to the measured
#: time, and below DRAG_LEAST coefficients the image shrinks instead, through DRAG_SCALES of the full size
DRAG_SECONDS = 0.04
DRAG_LEAST = 2048
DRAG_SCALES = (0.5, 0.375, 0.25)
#: a still view shows a better frame about this often; when the rest of it is expected within 1.5 times this, the
#: rest goes at once into the final frame (each frame costs a pass over every tile, a read-back and a PNG)
STILL_SECONDS = 0.3
#: the display window "auto" is taken from an image at this size (line integrals are in world units, so the
#: percentiles hardly depend on the image size) of at most WINDOW_COEFFICIENTS leading coefficients (at 1024^3
#: every coefficient took a minute)
WINDOW_SIZE = 128
WINDOW_COEFFICIENTS = 1 << 18


#: a model without coefficients (an all-zero volume) has one
#: blank final frame a view, and says so
NO_COEFFICIENTS = "nothing to show: the model has no coefficients (the volume is zero everywhere)"
#: a shaded frame of a model without coefficients through a transfer function that gives 0 an opacity: the data's box
#: fogged (docs/raytracing.md §10)
ZERO_FOG = ("the model has no coefficients (the volume is zero everywhere): the image is the value 0 as the transfer "
            "function classifies it, over the data's box")
#: a scalar model's shaded frame through a transfer function that gives no part of it any opacity
NOTHING_VISIBLE = ("nothing to show: the transfer function gives no part of the model any opacity (move or widen its "
                   "window, or raise its opacity)")


@dataclass(frozen=True)
class ViewState:
    """What one tab asks to see (checked by :func:`clwave.view.protocol.parse_view`)."""

    seq: int
    azimuth: float
    elevation: float
    zoom: float
    mode: str  # "xray" or "shaded"
    detail: float  # share of the kept coefficients splatted at most, (0, 1]
    window: tuple | None  # X-ray display window (lo, hi); None: the model's auto window
    moving: bool
    background: float  # shaded: grey level behind the volume, 0..1
    shading: bool  # shaded: Phong lighting (a headlight) or unlit emission
    # shaded, scalar model: (preset, centre, width, opacity) or the editor's points' TransferFunction, see
    # shaded.transfer_function
    tf: tuple | TransferFunction | None = None
    colour_map: str = "grey"  # X-ray, scalar model: one of colours.NAMES
    fov: float | None = None  # a perspective camera's vertical field of view, degrees; None: orthographic
    scale_bar: bool = False  # the page's scale bar (orthographic): in the saved image and the command (export.py)
    # shaded: (box (x0, y0, z0, x1, y1, z1) or None, planes ((px, py, pz, nx, ny, nz), ...)) in world units; None: none
    clip: tuple | None = None

    def clipping(self) -> Clip | None:
        """The shaded view's :class:`~clwave.Clip` (None: none), made here, not in the protocol: one that keeps
        nothing is the Clip's one line on the tab's status line (an InputError of its frames), not a refused socket."""
        if self.clip is None:
            return None
        return Clip.of_rows(*self.clip)


@dataclass
class Frame:
    """An encoded picture and its figures (JSON-ready)."""

    data: bytes
    mime: str
    figures: dict


def encode(picture: np.ndarray, lossless: bool) -> tuple:
    """``(bytes, mime)``: PNG (lossless, still frames) or JPEG (frames while dragging), by imageio's Pillow."""
    import imageio.v3 as iio

    if lossless:
        return iio.imwrite("<bytes>", picture, extension=".png", compress_level=1), "image/png"
    return iio.imwrite("<bytes>", picture, extension=".jpg", quality=85), "image/jpeg"


def check_tolerance(tolerance) -> float:
    """The shaded mode's tolerance, a positive number (checked before any work)."""
    if not finite_number(tolerance, "tolerance") > 0:
        raise InputError(f"tolerance={tolerance!r} must be a positive error per value (e.g. 1e-2)",
                         cli=f"--tolerance {tolerance:g} must be a positive error per value (e.g. 1e-2)")
    return float(tolerance)


class Source:
    """Common to both sources: the model, the image size and the framing.  A source is ready to render at once
    (:meth:`ready`), or after :meth:`prepare` has run on a thread of its own (the shaded one's bricks).  What a
    tab's frames are paced by is the tab's own (:meth:`pacing`), so that tabs dragging at once do not pace each
    other."""

    mode = ""
    capabilities: dict = {}
    patient = False  # the model's world is a patient's RAS+ (orientation.patient_world): the edges' letters R, A, S...

    def ready(self) -> bool:
        return True

    def prepare(self):
        """What :meth:`frames` needs that takes long, made off the render thread."""

    def __init__(self, wv, size):
        self.wv, self.size = wv, (int(size[0]), int(size[1]))
        H, W = self.size
        self.base_extent = Camera(0.0, 0.0, self.size).view(wv).pixel * W  # zoom 1: the content fills the image

    def camera(self, state: ViewState, scale=1.0, size=None) -> Camera:
        """The camera of ``state`` at ``scale`` of the image size (or at ``size`` (H, W), the same view): its extent
        the content's at zoom 1 over the zoom.  In perspective the eye is where the field of view ``fov`` frames the
        target's plane as zoom 1 does, and stays there: the zoom narrows the field of view (a lens), so the eye never
        enters the content (splatting refuses an eye within its basis functions' reach) below about 90 degrees."""
        H, W = self.size
        size = size or (max(8, round(H * scale)), max(8, round(W * scale)))
        if state.fov is None:
            return Camera(state.azimuth, state.elevation, size, extent=self.base_extent / state.zoom)
        half = math.tan(math.radians(state.fov) / 2.0)
        fov = state.fov if state.zoom == 1.0 else math.degrees(2.0 * math.atan(half / state.zoom))  # 30, not 30.000…4
        return Camera(state.azimuth, state.elevation, size, perspective=True, fov=fov,
                      distance=self.base_extent * H / W / (2.0 * half))

    def _scale_bar(self, state) -> list | None:
        """``[length, label]`` of the scale bar the page draws over an orthographic view (as ``--scale-bar`` without
        a length draws it, io/images.py), None in perspective."""
        from ..io.images import length_label, nice_length

        if state.fov is not None:
            return None
        length = nice_length(self.base_extent / state.zoom)
        return [length, length_label(length, self.wv.unit)]

    def pacing(self):
        """A tab's pacing state of this source's frames (passed to :meth:`frames`)."""

    def histogram(self) -> dict | None:
        """The values behind the page's transfer-function editor (``range``, ``counts``), where the source has them."""

    def frames(self, state: ViewState, pace):
        raise NotImplementedError

    def _frame(self, state, picture, lossless, figures, start) -> Frame:
        encode_start = time.perf_counter()
        data, mime = encode(picture, lossless)
        return Frame(data, mime, dict(figures, mode=self.mode, seq=state.seq, height=picture.shape[0],
                                      width=picture.shape[1], azimuth=state.azimuth, elevation=state.elevation,
                                      extent=self.base_extent / state.zoom, fov=state.fov,
                                      scale_bar=self._scale_bar(state),
                                      orientation=orientation.edges(self.camera(state), self.patient),
                                      encode_seconds=time.perf_counter() - encode_start,
                                      elapsed=time.perf_counter() - start))


@dataclass
class XrayPace:
    """One tab's X-ray pacing: the next drag frame's prefix and image size (an index in :data:`DRAG_SCALES`), the
    view of its last drag frame, and ``(view, coefficients)`` of its last still frame."""

    drag_count: int
    drag_scale: int = 0
    dragged: tuple | None = None
    still: tuple = (None, 0)


class XraySource(Source):
    """X-ray frames by splatting prefixes of the ranked coefficients with one reused :class:`SplatRenderer`
    (paper §5.2): while dragging, a smaller image of a prefix sized to the measured render time; when still,
    growing prefixes accumulated into one framebuffer up to ``detail`` of the kept coefficients, a frame about
    every :data:`STILL_SECONDS` (docs/viewer.md §2).

    ``complete``: False while the model is a prefix of a ``.clw`` file whose rest is being read; then no frame is
    final, and :meth:`swap` extends the renderer to the whole model (docs/viewer.md §2); where the rest cannot be
    read the server sets it, the prefix being the model served."""

    mode = "xray"

    def __init__(self, wv, size, renderer: SplatRenderer, complete=True):
        super().__init__(wv, size)
        self.capabilities = dict(detail=True, window=True, colour_map=wv.channels == 1)  # an RGBA model's is colour
        self.r, self.complete = renderer, complete
        self.rate = None  # seconds per coefficient of the last still view (its footprints included)
        n = min(renderer.count, WINDOW_COEFFICIENTS)
        acc = renderer.begin(Camera(30.0, 20.0, WINDOW_SIZE), upto=n)
        acc.splat(0, n)
        self.auto_window = tuple(float(v) for v in resolve_window(acc.image()[..., :3], "auto"))

    def pacing(self) -> XrayPace:
        return XrayPace(min(max(DRAG_LEAST, self.r.count // 100), self.r.count))

    def swap(self, wv, groups: list):
        """The whole model in place of the prefix, its ranked ``groups`` beginning with the prefix's coefficients
        (``SplatRenderer.extend``; on the render thread, between stages): frames under way go on to the prefix's
        last coefficient, from what they began with, and none of them is final."""
        self.r.extend(wv, groups)
        self.wv, self.complete = wv, True

    def frames(self, state: ViewState, pace: XrayPace):
        start = time.perf_counter()
        # a swap meanwhile does not change a view under way: its coefficients and figures stay the prefix's
        r, complete, energy = self.r, self.complete, self.r.energy
        total = r.count
        limit = min(total, max(1, round(state.detail * total)))  # 0 for a model without coefficients
        window = state.window or colours.centred(self.auto_window, state.colour_map)
        here = (state.azimuth, state.elevation, state.zoom, state.fov)
        # a drag frame while moving, and first for a still view the page has no drag frame of (a page's first, a
        # reset): a smaller image of a prefix, with the footprints of the bands it reaches only
        if state.moving or here != pace.dragged:
            count = min(pace.drag_count, limit)
            acc = r.begin(self.camera(state, DRAG_SCALES[pace.drag_scale]), upto=count)
            acc.splat(0, count)
            image = acc.image()
            seconds = time.perf_counter() - start
            self._pace(pace, total, count, seconds)
            pace.dragged = here
            yield self._xray_frame(state, energy, total, complete, image, count, window, False, seconds, start)
            if state.moving:
                return
        stage = time.perf_counter()
        acc = r.begin(self.camera(state))
        done, busy = 0, time.perf_counter() - stage
        # never a worse frame than the page shows: the same view again (the whole model swapped in) starts from as
        # many coefficients as its last still frame
        least = pace.still[1] if pace.still[0] == (here, state.detail) else 0
        while True:  # at least one frame, the last with all of ``limit`` (none: a blank final frame)
            stage = time.perf_counter()
            count = min(limit, max(done + 1, self._still_count(done, limit, pace.drag_count), least))
            acc.splat(done, count - done)
            image = acc.image()
            done, seconds = count, time.perf_counter() - stage
            busy += seconds
            if done == limit and limit:
                self.rate = busy / limit
            pace.still = ((here, state.detail), done)
            yield self._xray_frame(state, energy, total, complete, image, done, window, complete and done == limit,
                                   seconds, start)
            if done == limit:
                return

    @staticmethod
    def _pace(pace: XrayPace, total, count, seconds):
        """The tab's next drag frame's prefix and size: the prefix scaled towards :data:`DRAG_SECONDS` (at most
        doubled or halved a frame); where it would fall below :data:`DRAG_LEAST` coefficients the image shrinks a
        step, and where it grows past four times that the image grows back a step."""
        want = count * float(np.clip(DRAG_SECONDS / max(seconds, 1e-4), 0.5, 2.0))
        least = min(DRAG_LEAST, total)
        if want < least and pace.drag_scale < len(DRAG_SCALES) - 1:
            pace.drag_scale, want = pace.drag_scale + 1, least
        elif want > 4 * least and pace.drag_scale > 0:
            pace.drag_scale, want = pace.drag_scale - 1, want / 2
        pace.drag_count = int(min(max(want, least), total))

    def _still_count(self, done: int, limit: int, drag_count: int) -> int:
        """The coefficients after the next still frame: at least twice ``done``, about :data:`STILL_SECONDS` more
        of splatting at the last still view's rate, all ``limit`` where the rest is expected within 1.5 times
        that (before a first still view: doubling from the tab's drag prefix)."""
        if self.rate is None:
            return int(min(limit, max(2 * done, drag_count)))
        step = STILL_SECONDS / self.rate
        return int(limit if limit - done <= 1.5 * step else min(limit, done + max(done, step)))

    def _xray_frame(self, state, energy, total, complete, image, count, window, final, seconds, start) -> Frame:
        captured = float(energy[count - 1] / energy[-1]) if count and energy[-1] > 0 else 1.0
        picture = RenderResult(image, dict(mode="xray")).to_uint8(window)
        colour_map = state.colour_map if self.capabilities["colour_map"] else None  # an RGBA model's is its colours
        if colour_map:
            picture = colours.apply(picture, colour_map)
        figures = dict(final=final, colour_map=colour_map, coefficients=count, fraction=count / max(total, 1),
                       voxel_fraction=count / self.wv.n_voxels, prefix=not complete,
                       # the coefficient energy not yet splatted: the relative L2 error of the model drawn
                       error=float(np.sqrt(max(0.0, 1.0 - captured))), error_kind="relative L2 (coefficients left)",
                       window=list(window), seconds=seconds)
        if not total:  # the page's status line says why the image is blank
            figures["note"] = NO_COEFFICIENTS
        return self._frame(state, picture, final or not state.moving, figures, start)
