"""Progressive ray tracing (docs/raytracing.md §9): frames from cheap to exact, full detail on images 2^k times
smaller per side, each twice the side of the one before, then the full image at the requested tolerance: bit for bit
the image ``RayTracer.render`` gives.  Each frame carries the estimate of its error against the final image, the
step from the frame before (or from a pilot at half its size); the last preview has 1/16 of the final image's rays,
so the previews cost about 1/12 of the final render.  An image too small to reduce gets the tracer's coarser
details instead, each shown where it halves the error of the frame before.  :meth:`RayTracer.refine` is the same
sequence for a viewer, which stops iterating when the view changes.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import ClwaveWarning, InputError, warn_outside, whole_number
from ..model.camera import Camera
from ..model.conebeam import ConeBeam, check_camera, view_record
from ..frames import ErrorEstimate, FinalImage, Frame, check_budget, check_error, reached

#: the smallest reduced image side: below it a frame no longer halves the error of the one before
#: (docs/raytracing.md §9)
MIN_SIDE = 32
#: the max estimate's margin over the step: the max error of interpolation across a sharp edge falls at first order at
#: best (to half when the pixels halve, less at an edge not resolved yet); 1.5 steps bound it where it falls to 3/5
#: or less (docs/raytracing.md §9)
MAX_MARGIN = 1.5
#: the last preview's reduction per side: the final image has 16 times its rays, and the previews before it (each a
#: quarter of the next) cost at most 1/12 of the final render (docs/raytracing.md §9)
LAST_REDUCTION = 4


@dataclass(kw_only=True, repr=False)
class RaytraceFrame(Frame):
    """One step of progressive ray tracing: ``image`` (H, W, C) at the full size, rendered at ``detail`` on an
    image ``reduction`` times smaller per side (then interpolated); errors as :class:`~clwave.frames.Frame`
    (the final image: full detail, full size, the requested tolerance)."""

    detail: int
    reduction: int

    def own_figures(self) -> dict:
        return dict(detail=self.detail, reduction=self.reduction)


def schedule(size, details=(0,), steps=None) -> list:
    """``[(detail, reduction)]`` from cheap to exact: the finest of the tracer's ``details`` (full detail, unless it
    holds coarser ones only) on images ``2^top, ..., 8, 4`` times smaller per side (the largest reduction leaves sides
    of :data:`MIN_SIDE` at least; an image under ``4 MIN_SIDE`` a side gets the one it allows), then on the full image
    (docs/raytracing.md §9).  An image too small to reduce gets a frame per coarser detail the tracer holds, coarsest
    first, on the full image (shown where it halves the error of the frame before).  ``steps`` keeps the last that
    many."""
    finest = min(details)
    top = int(np.floor(np.log2(max(1, min(size) / MIN_SIDE))))
    last = min(top, int(np.log2(LAST_REDUCTION)))
    frames = ([(finest, 2 ** k) for k in range(top, last - 1, -1)] if top else
              [(d, 1) for d in sorted(details)[::-1] if d != finest])
    frames = frames + [(finest, 1)]
    return frames if steps is None else frames[-int(steps):]


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


def frames(tracer, camera: Camera | ConeBeam, options: dict, steps=None, budget=None, error=None, final=None,
           previous=None):
    """The frames of :func:`clwave.progressive.raytrace_progressive` from a :class:`~clwave.RayTracer` (its
    :meth:`~clwave.RayTracer.refine`, and a staged tracer's once its full stage is ready), arguments checked first.
    ``final``: the :class:`~clwave.frames.FinalImage` the frames measure against (one of ``tracer``'s renders of
    ``camera`` with ``options``), where frames made before these share it; ``previous``: the last of those frames."""
    check_error(error)
    if steps is not None and (not whole_number(steps) or steps < 1):
        raise InputError(f"steps={steps!r} must be a whole number of frames, at least 1",
                         cli=f"--steps {steps} must be a whole number of frames, at least 1")
    check_budget(budget)
    check_camera(camera)
    final = final or FinalImage(lambda: tracer.render(camera, **options).image)
    return _frames(tracer, camera, options, steps, budget, error, final, previous)


def _frames(tracer, camera, options, steps, budget, error, final, shown):
    view = camera.view(tracer.wv)
    plan = schedule(view.size, tracer.details, steps)
    if steps is not None and len(plan) < steps:  # the schedule halves the image per frame down to a least side
        (h, w), many = view.size, f"{len(plan)} progressive ray-tracing frame{'s' if len(plan) != 1 else ''}"
        warn_outside(ClwaveWarning(f"a {w}x{h} image allows {many}, not steps={steps}; a bigger image allows more",
                                   cli=f"a {w}x{h} image allows {many}, not --steps {steps}; a bigger --size "
                                       f"allows more"))
    start, steps_made, last, made = time.perf_counter(), ErrorEstimate(), None, 0

    def render(detail, reduction):  # the tracer's render of an image reduction times smaller per side
        res = tracer.render(camera if reduction == 1 else camera.reduced(reduction, view), detail=detail,
                            **options)
        # the meta of the camera given, whose image the frame is (upsampled), not of the reduced one
        return upsample(res.image, view.size, reduction), dict(res.meta, **view_record(camera, view, tracer.wv.unit))

    for index, (detail, reduction) in enumerate(plan):
        if budget is not None and last is not None:
            elapsed = time.perf_counter() - start
            if elapsed + last * (plan[index - 1][1] / reduction) ** 2 > budget:
                return
        if index == 0 and reduction > 1:  # the first frame's pilot: the step from an image half its size (§9)
            steps_made.add(render(detail, 2 * reduction)[0])
        t0 = time.perf_counter()  # the frame's own render, not its pilot's: the budget's prediction of the next
        image, meta = render(detail, reduction)  # frame scales it
        frame = RaytraceFrame(index=made, image=image, seconds=0.0, estimated_relative_rms_error=0.0,
                              estimated_relative_max_error=0.0, meta=meta, _final=final, detail=detail,
                              reduction=reduction)
        last = time.perf_counter() - t0
        if (detail, reduction) == plan[-1]:
            final.image = image
        elif reduction == 1:  # a coarser detail on the full image: measured against the final image, rendered first,
            # and shown where it halves the error of the frame before (docs/raytracing.md §9)
            frame.estimated_relative_rms_error = frame.relative_rms_error
            frame.estimated_relative_max_error = frame.relative_max_error
            if shown is not None and frame.relative_rms_error > shown.relative_rms_error / 2:
                continue
        else:  # docs/raytracing.md §9: the step from the frame before, at half this frame's size
            rms, top = steps_made.add(image)
            frame.estimated_relative_rms_error, frame.estimated_relative_max_error = rms, top * MAX_MARGIN
        frame.seconds, made, shown = time.perf_counter() - start, made + 1, frame
        yield frame
        if reached(frame, error):
            return
