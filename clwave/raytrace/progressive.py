"""Progressive ray tracing (docs/raytracing.md §9): frames from cheap to exact, a coarse detail on a reduced
image first, then finer details on larger images, ending at full detail, the full image and the requested
tolerance: bit for bit the image ``RayTracer.render`` gives.  Each frame carries the estimate of its error
against the final image (:func:`estimate`, from full-detail pilots on images of the frame's size and half of it);
:meth:`RayTracer.refine` is the same sequence for a viewer, which stops iterating when the view changes.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..model.camera import Camera
from ..model.conebeam import ConeBeam, check_camera
from ..frames import FinalImage, Frame, check_error, reached

#: the smallest reduced image side: below it a frame no longer halves the error of the one before
#: (docs/raytracing.md §9)
MIN_SIDE = 32


@dataclass(kw_only=True)
class RaytraceFrame(Frame):
    """One step of progressive ray tracing: ``image`` (H, W, C) at the full size, rendered at ``detail`` on an
    image ``reduction`` times smaller per side (then interpolated); errors as :class:`~clwave.frames.Frame`
    (the final image: full detail, full size, the requested tolerance)."""

    detail: int
    reduction: int

    def own_figures(self) -> dict:
        return dict(detail=self.detail, reduction=self.reduction)


def schedule(levels: int, size, steps=None) -> list:
    """``[(detail, reduction)]`` from cheap to exact: detail d on an image ``2^(d + 1)`` times smaller per side, from
    the coarsest detail ``levels`` to full detail, then full detail on the full image (docs/raytracing.md §9); a
    frame whose image would have a side below :data:`MIN_SIDE` is left out, and an image too small to reduce gets a
    frame per detail at its full size.  ``steps`` keeps the last that many."""
    top = int(np.floor(np.log2(max(1, min(size) / MIN_SIDE))))  # the largest reduction: 2^top
    if top == 0:
        frames = [(d, 1) for d in range(levels, -1, -1)]
    else:
        frames = [(d, 2 ** (d + 1)) for d in range(levels, -1, -1) if d + 1 <= top] + [(0, 1)]
    return frames if steps is None else frames[-int(steps):]


def reduced_camera(view, camera: Camera | ConeBeam, reduction: int) -> Camera | ConeBeam:
    """The camera of the same ``view`` with ``reduction`` times larger pixels (sides rounded up, same centre)."""
    return camera.reduced(reduction, view)


def upsample(image: np.ndarray, size, reduction: int) -> np.ndarray:
    """A reduced image at the full ``size``: linear interpolation at the full pixels' centres (the edge pixels
    extended), one axis at a time."""
    if reduction == 1:
        return image
    for axis, n in enumerate(size):
        m = image.shape[axis]
        at = np.clip((np.arange(n) + 0.5 - n / 2) / reduction + m / 2 - 0.5, 0, m - 1)
        lo = np.minimum(at.astype(np.intp), max(m - 2, 0))
        w = (at - lo).astype(np.float32).reshape((-1,) + (1,) * (image.ndim - 1 - axis))
        a, b = np.take(image, lo, axis), np.take(image, np.minimum(lo + 1, m - 1), axis)
        image = a + w * (b - a)
    return image.astype(np.float32, copy=False)


def frames(tracer, camera: Camera | ConeBeam, options: dict, steps=None, budget=None, error=None):
    """The frames of :func:`clwave.progressive.raytrace_progressive` from a :class:`~clwave.RayTracer` (its
    :meth:`~clwave.RayTracer.refine`), arguments checked first."""
    check_error(error)
    if steps is not None and (isinstance(steps, bool) or int(steps) != steps or steps < 1):
        raise InputError(f"steps={steps!r} must be a whole number of frames, at least 1",
                         cli=f"--steps {steps} must be a whole number of frames, at least 1")
    if budget is not None and not (np.isfinite(budget) and budget > 0):
        raise InputError(f"budget={budget!r} must be a positive number of seconds",
                         cli=f"--budget {budget:g} must be a positive number of seconds")
    if not tracer.lod:
        raise InputError("progressive ray tracing needs a tracer of every detail: RayTracer(wv, lod=True)")
    check_camera(camera)
    return _frames(tracer, camera, options, steps, budget, error)


def _frames(tracer, camera, options, steps, budget, error):
    view = camera.view(tracer.wv)
    plan = schedule(tracer.wv.levels, view.size, steps)
    final = FinalImage(lambda: tracer.render(camera, **options).image)
    start, made = time.perf_counter(), {}

    def render(detail, reduction):  # each (detail, reduction) once: frames and the estimate's full-detail pilots
        if (detail, reduction) not in made:
            res = tracer.render(camera if reduction == 1 else reduced_camera(view, camera, reduction), detail=detail,
                                **options)
            made[detail, reduction] = upsample(res.image, view.size, reduction), res.meta
        return made[detail, reduction]

    last = None
    for index, (detail, reduction) in enumerate(plan):
        if budget is not None and last is not None:
            elapsed = time.perf_counter() - start
            if elapsed + last * (plan[index - 1][1] / reduction) ** 2 > budget:
                return
        t0 = time.perf_counter()
        image, meta = render(detail, reduction)
        if reduction == 1 and detail == 0:
            final.image, rms, top = image, 0.0, 0.0
        else:  # docs/raytracing.md §9: what the detail misses at this size, and what the size misses
            rms, top = estimate(image, render(0, reduction)[0], render(0, 2 * reduction)[0])
        last = time.perf_counter() - t0
        frame = RaytraceFrame(index=index, image=image, seconds=time.perf_counter() - start,
                              estimated_relative_rms_error=rms, estimated_relative_max_error=top, meta=meta,
                              _final=final, detail=detail, reduction=reduction)
        yield frame
        if reached(frame, error):
            return


def estimate(image, full, half) -> tuple:
    """(relative RMS, relative max) estimated error of a frame ``image`` against the final image, from ``full``
    (full detail at the frame's size) and ``half`` (full detail at half its size), all at the full size
    (docs/raytracing.md §9): the frame's distance from ``full``, plus ``full``'s from ``half`` for what the
    frame's size misses.  Relative to the largest magnitude of ``full``."""
    peak = max(float(np.max(np.abs(full), initial=0.0)), np.finfo(np.float32).tiny)
    detail, size = image - full, full - half
    rms = float(np.sqrt(np.mean(detail ** 2))) + float(np.sqrt(np.mean(size ** 2)))
    top = float(np.max(np.abs(detail), initial=0.0)) + float(np.max(np.abs(size), initial=0.0))
    return rms / peak, top / peak
