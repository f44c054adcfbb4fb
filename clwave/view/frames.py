"""Frame sources of the viewer (docs/viewer.md §2): the pictures of one view, cheapest first.

A source turns a :class:`ViewState` into an iterator of :class:`Frame` s.  While the user drags
(``moving``) it yields one cheap frame; when the view is still it refines the same view and yields each
better frame as it completes, the last one ``final``.  The server advances the iterator one frame at a
time on its render thread and drops it as soon as the view changes, so a stage is the unit of abandoned
work.  This is the seam where level-of-detail frames (a ``refine(camera)`` generator of the ray tracer)
and render-time transfer functions plug in: a source declares what it can act on in ``capabilities``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import InputError, finite_number
from ..io.result import RenderResult, resolve_window
from ..model.camera import Camera
from ..splat.renderer import SplatRenderer

#: frames while dragging: this share of the image size (a view's footprints and framebuffers shrink with it)
DRAG_SCALE = 0.5
#: X-ray frames while dragging aim at this many seconds of splatting (the coefficient prefix adapts to it)
DRAG_SECONDS = 0.06
#: shaded frames while dragging and the first when still: the tolerance times this
DRAG_LOOSEN = 10.0
#: still X-ray views refine from the drag prefix to the detail kept, the coefficients growing by at most this
#: factor from frame to frame (fewer, larger steps reach the final frame sooner: each costs a read-back and a PNG)
STILL_GROWTH = 4.0
#: the display window "auto" is taken from an image of every coefficient at this size (line integrals are in
#: world units, so the percentiles hardly depend on the image size)
WINDOW_SIZE = 128


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


def still_counts(first: int, limit: int) -> list:
    """Coefficient counts of a still view's frames: ``first`` to ``limit`` in equal ratios of at most
    :data:`STILL_GROWTH`.

    >>> still_counts(1000, 64000)
    [1000, 4000, 16000, 64000]
    """
    steps = int(np.ceil(np.log(limit / first) / np.log(STILL_GROWTH) - 1e-9)) if limit > first else 0
    return [int(round(first * (limit / first) ** (i / steps))) for i in range(steps)] + [limit]


class Source:
    """Common to both sources: the model, the image size and the framing."""

    mode = ""
    capabilities: dict = {}

    def __init__(self, wv, size):
        self.wv, self.size = wv, (int(size[0]), int(size[1]))
        H, W = self.size
        self.base_extent = Camera(0.0, 0.0, self.size).view(wv).pixel * W  # zoom 1: the content fills the image

    def camera(self, state: ViewState, scale=1.0) -> Camera:
        H, W = self.size
        size = (max(8, round(H * scale)), max(8, round(W * scale)))
        return Camera(state.azimuth, state.elevation, size, extent=self.base_extent / state.zoom)

    def frames(self, state: ViewState):
        raise NotImplementedError

    def _frame(self, state, picture, lossless, figures, start) -> Frame:
        encode_start = time.perf_counter()
        data, mime = encode(picture, lossless)
        return Frame(data, mime, dict(figures, mode=self.mode, seq=state.seq, height=picture.shape[0],
                                      width=picture.shape[1], azimuth=state.azimuth, elevation=state.elevation,
                                      extent=self.base_extent / state.zoom,
                                      encode_seconds=time.perf_counter() - encode_start,
                                      elapsed=time.perf_counter() - start))


class XraySource(Source):
    """X-ray frames by splatting prefixes of the ranked coefficients with one reused :class:`SplatRenderer`
    (paper §5.2): a smaller image of a prefix sized to keep up while dragging, then growing prefixes of one
    framebuffer up to ``detail`` of the kept coefficients when still (docs/splatting.md §5)."""

    mode = "xray"
    capabilities = dict(detail=True, window=True)

    def __init__(self, wv, size, renderer: SplatRenderer):
        super().__init__(wv, size)
        self.r = renderer
        self.drag_count = max(1, min(renderer.count, max(1024, renderer.count // 100)))
        result = RenderResult(self._image(Camera(30.0, 20.0, WINDOW_SIZE), renderer.count))
        self.auto_window = tuple(float(v) for v in resolve_window(result.image[..., :3], "auto"))

    def _image(self, camera, count):
        acc = self.r.begin(camera)
        acc.splat(0, count)
        return acc.image()

    def frames(self, state: ViewState):
        start = time.perf_counter()
        r = self.r
        limit = max(1, int(np.ceil(state.detail * r.count)))
        window = state.window or self.auto_window
        if state.moving:
            count = min(self.drag_count, limit)
            image = self._image(self.camera(state, DRAG_SCALE), count)
            seconds = time.perf_counter() - start
            # the next drag frame's prefix: scaled towards DRAG_SECONDS, at most doubled or halved per frame
            self.drag_count = int(np.clip(count * np.clip(DRAG_SECONDS / max(seconds, 1e-4), 0.5, 2.0),
                                          min(1024, r.count), r.count))
            yield self._xray_frame(state, image, count, window, False, seconds, start)
            return
        acc = r.begin(self.camera(state))
        done = 0
        for count in still_counts(min(self.drag_count, limit), limit):
            stage = time.perf_counter()
            acc.splat(done, count - done)
            done = count
            image = acc.image()
            yield self._xray_frame(state, image, done, window, done == limit, time.perf_counter() - stage, start)

    def _xray_frame(self, state, image, count, window, final, seconds, start) -> Frame:
        energy = self.r.energy
        captured = float(energy[count - 1] / energy[-1]) if count and energy[-1] > 0 else 1.0
        picture = RenderResult(image, dict(mode="xray")).to_uint8(window)
        figures = dict(final=final, coefficients=count, fraction=count / max(self.r.count, 1),
                       voxel_fraction=count / self.wv.n_voxels,
                       # the coefficient energy not yet splatted: the relative L2 error of the model drawn
                       error=float(np.sqrt(max(0.0, 1.0 - captured))), error_kind="relative L2 (coefficients left)",
                       window=list(window), seconds=seconds)
        return self._frame(state, picture, final or not state.moving, figures, start)


class ShadedSource(Source):
    """Shaded emission-absorption frames by one reused :class:`~clwave.RayTracer`: a smaller image at a looser
    tolerance while dragging; when still the full image at the looser, then the given tolerance.  Needs an
    RGBA (pre-classified) model: transfer functions at render time (``capabilities["tf"]``) are not there yet."""

    mode = "shaded"
    capabilities = dict(tf=False, background=True, shading=True)

    def __init__(self, wv, size, tolerance, device=None):
        super().__init__(wv, size)
        self.tolerance, self.device, self._tracer = check_tolerance(tolerance), device, None

    @property
    def tracer(self):
        """The :class:`~clwave.RayTracer`, made on first use (its bricks take a while)."""
        if self._tracer is None:
            from ..raytrace.tracer import RayTracer
            self._tracer = RayTracer(self.wv, device=self.device)
        return self._tracer

    def frames(self, state: ViewState):
        start = time.perf_counter()
        stages = [(DRAG_SCALE, self.tolerance * DRAG_LOOSEN)] if state.moving else \
            [(1.0, self.tolerance * DRAG_LOOSEN), (1.0, self.tolerance)]
        for i, (scale, tolerance) in enumerate(stages):
            stage = time.perf_counter()
            result = self.tracer.render(self.camera(state, scale), tolerance=tolerance, shading=state.shading)
            final = not state.moving and i == len(stages) - 1
            picture = result.to_uint8(background=(state.background,) * 3)
            figures = dict(final=final, tolerance=tolerance, error=tolerance, error_kind="absolute, per value",
                           seconds=time.perf_counter() - stage)
            yield self._frame(state, picture, final or not state.moving, figures, start)
