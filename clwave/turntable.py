"""Turntables (docs/coordinates.md §4): ``n`` views of one camera turned through 360 degrees about an axis (the
world's z, the elevation kept, unless another is given), and their pictures through one window, so that an X-ray
turntable does not flicker.  :func:`turntable` and ``clwave render --turntable`` alike."""

from __future__ import annotations

import base64
import html
import inspect
import io
from pathlib import Path

import numpy as np

from .errors import InputError, reals
from .io.files import check_suffix, write_atomic
from .io.images import check_frame_time, gif_to, write_gif
from .io.progress import progress
from .io.result import RenderResult, reduced, resolve_window, summary
from .model.camera import Camera

METHODS = ("splat", "raytrace")
#: the axes a turntable names: z turns the azimuth (:meth:`Camera.rotated`'s None)
AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": None}
#: seconds a view is shown in a turntable's GIF (:meth:`Turntable.save`'s default, and a notebook's)
FRAME_TIME = 0.1


def turntable_axis(axis):
    """A turntable's ``axis`` as :meth:`Camera.rotated` takes it: "x", "y" or "z" (None), or a direction (x, y, z)
    as a unit vector; anything else refused in one line."""
    if isinstance(axis, str) and axis in AXES:
        return AXES[axis]
    what = "'x', 'y', 'z' or a direction (x, y, z)"
    if isinstance(axis, str):
        raise InputError(f"axis={axis!r} must be {what}")
    k = reals(axis, "axis", 3, what)
    largest = float(np.max(np.abs(k)))  # divided by first: the norm of (1e308, 1e308, 0) would overflow
    if not 0 < largest < float("inf"):
        raise InputError(f"axis={axis!r} must be a direction (x, y, z): finite, not all zero",
                         cli=f"--turntable-axis {','.join(f'{x:g}' for x in k)} must be a direction: finite, not "
                             f"all zero")
    k = k / largest
    return tuple(k / np.linalg.norm(k))


#: host memory a turntable holds per pixel of a view, at the most: its float32 image of up to 4 channels, their stack
#: for the one window or the .npy (the colour channels) and its 8-bit picture
VIEW_PIXEL_BYTES = 4 * 4 + 4 * 3 + 4


def turntable_cameras(camera, n, axis="z") -> list:
    """``camera`` turned by ``360 i / n`` degrees about ``axis`` (:func:`turntable_axis`) for i in 0 .. n-1; ``n``
    checked (a whole number >= 1), and the views' images against the host memory available
    (:data:`VIEW_PIXEL_BYTES`), before any is rendered."""
    from .device.memory import check_fits

    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise InputError(f"n={n!r} must be the number of views, a whole number >= 1 (e.g. 24)",
                         cli=f"--turntable {n} needs N >= 1")
    if not isinstance(camera, Camera):
        raise InputError(f"camera={type(camera).__name__} must be a clwave.Camera (a turntable turns it about an "
                         f"axis), or None for the default")
    axis = turntable_axis(axis)
    H, W = camera.size
    check_fits(int(n) * H * W * VIEW_PIXEL_BYTES, f"a turntable of {n} {H}x{W} views",
               "give fewer views (--turntable N, n=) or a smaller size")
    return [camera.rotated(360.0 * i / n, axis) for i in range(int(n))]


class Turntable:
    """The views of a turntable: ``results`` (a :class:`RenderResult` each), ``images`` (their (N, H, W, C)
    float32 stack) and ``meta`` (the first view's, with ``turntable_seconds``, each view's render time, and
    ``turntable_views``, each view's ``camera`` and ``pixel``)."""

    def __init__(self, results):
        self.results = list(results)
        if not self.results:  # no view has an image size or a first view's meta
            raise InputError("a Turntable needs at least one view: give clwave.turntable n >= 1")
        first = self.results[0].meta
        self.meta = dict(first, turntable_seconds=[r.seconds for r in self.results],
                         turntable_views=[dict(camera=r.meta["camera"], pixel=r.meta["pixel"]) for r in self.results])

    @classmethod
    def rendered(cls, render, cameras) -> "Turntable":
        """The views ``render(camera)`` of ``cameras``, in order, a bar counting them where there are several."""
        shown = None if len(cameras) > 1 else False  # one view is a render, no turn to count
        return cls(render(cam) for cam in progress(cameras, desc="turntable views", enabled=shown))

    def __len__(self) -> int:
        return len(self.results)

    def __repr__(self) -> str:
        return f"Turntable({summary(self.images, self.meta)}, {sum(self.meta['turntable_seconds']):.3g} s)"

    def _repr_html_(self) -> str:
        """The turn as a notebook shows it: its :meth:`save`'s GIF, made in memory from the views' images (rendered
        once) as :meth:`RenderResult._repr_png_` reduces a picture, in an ``<img>``."""
        buffer = io.BytesIO()
        gif_to(buffer, [reduced(p) for p in self.pictures()], FRAME_TIME)
        gif = base64.b64encode(buffer.getvalue()).decode()
        return f'<img src="data:image/gif;base64,{gif}" alt="{html.escape(repr(self))}"/>'

    def __getitem__(self, i) -> RenderResult:
        return self.results[i]

    @property
    def images(self) -> np.ndarray:
        return np.stack([r.image for r in self.results])

    def window(self, window="auto", colour_map=None):
        """The ``(lo, hi)`` every X-ray view in ``colour_map`` is shown through: ``"auto"`` resolved from all the views
        together (one window for the whole turn: no flicker); None for shaded views, which have none."""
        if not self.results[0].is_xray:
            return None
        return resolve_window(np.stack([r.image[..., :3] for r in self.results]), window, colour_map)

    def pictures(self, window="auto", background=None, scale_bar=None, unit=None, colour_map=None,
                 colour_bar=False) -> list:
        """Each view's 8-bit picture (:meth:`RenderResult.picture`), X-rays through the one :meth:`window`."""
        shared = self.window(window, colour_map) if self.results[0].is_xray else window
        return [r.picture(shared, background, scale_bar=scale_bar, unit=unit, colour_map=colour_map,
                          colour_bar=colour_bar)
                for r in self.results]

    def save(self, path, *, window="auto", background=None, scale_bar=None, unit=None, colour_map=None,
             colour_bar=False, frame_time=FRAME_TIME, overwrite=False) -> Path:
        """Write ``.gif`` (the :meth:`pictures`, looping, each shown ``frame_time`` seconds, to the hundredth),
        ``.npy`` (the (N, H, W, C) float32 :attr:`images`) or ``.json`` (:attr:`meta`)."""
        path = check_suffix(path, (".gif", ".npy", ".json"))
        given = [f"{name}=" for name, value in (("window", None if isinstance(window, str) and window == "auto" else
                                                 window), ("background", background), ("scale_bar", scale_bar),
                                                ("colour_map", colour_map), ("colour_bar", colour_bar or None))
                 if value is not None]
        if given and path.suffix.lower() != ".gif":
            raise InputError(f"{' and '.join(given)} set a .gif's pictures; {path} holds the views' values or "
                             f"figures: leave {'them' if len(given) > 1 else 'it'} out")
        frame_time = check_frame_time(frame_time)
        if path.suffix.lower() == ".gif":
            return write_gif(path, self.pictures(window, background, scale_bar, unit, colour_map, colour_bar),
                             frame_time, overwrite)
        images = self.images
        if path.suffix.lower() == ".npy":
            if images.size != np.count_nonzero(np.isfinite(images)):
                raise InputError(f"the views have non-finite values (NaN/Inf), so {path} was not written")
            return write_atomic(path, lambda fh: np.save(fh, images), overwrite)
        return RenderResult(self.results[0].image, self.meta).save(path, overwrite=overwrite)


def turntable(wv, n, camera=None, method="splat", axis="z", **options) -> Turntable:
    """``n`` views of ``wv`` through ``camera`` (default ``Camera()``) turned through 360 degrees about ``axis``: "z"
    (default; the azimuth turned), "x", "y" or a direction (x, y, z), right-handed (:func:`turntable_cameras`), by
    ``method`` "splat" (:func:`clwave.splat`) or "raytrace" (:func:`clwave.raytrace`)
    with its ``options``; ``.save("turn.gif")`` writes them as ``clwave render --turntable`` does."""
    from .raytrace.tracer import raytrace
    from .splat.renderer import splat

    if not isinstance(method, str) or method not in METHODS:
        raise InputError(f"method={method!r} must be one of {', '.join(map(repr, METHODS))}")
    draw = splat if method == "splat" else raytrace
    cameras = turntable_cameras(Camera() if camera is None else camera, n, axis)
    try:  # an option the method has not, named before the first view
        inspect.signature(draw).bind(wv, cameras[0], **options)
    except TypeError as e:
        raise InputError(f"{method} takes no such option ({e}): see help(clwave.{method})") from None
    return Turntable.rendered(lambda cam: draw(wv, cam, **options), cameras)
