"""Progressive rendering, whatever the method (docs/raytracing.md §9, docs/splatting.md §5): frames from cheap
to exact (:mod:`clwave.frames`), by splatting (:mod:`clwave.splat.progressive`) or ray tracing
(:meth:`clwave.RayTracer.refine`, :mod:`clwave.raytrace.progressive`).
"""

from __future__ import annotations

from .errors import InputError
from .raytrace.tracer import RayTracer, shared_tracer
from .splat.progressive import progressive as splat_progressive


def progressive(wv, camera, steps=None, budget=None, device=None, *, method="splat", error=None, **options):
    """Yield frames from cheap to exact: :func:`clwave.splat.progressive.progressive` (``method="splat"``,
    :class:`~clwave.splat.progressive.ProgressiveFrame` s) or :func:`raytrace_progressive`
    (``method="raytrace"``, :class:`~clwave.raytrace.progressive.RaytraceFrame` s); ``options`` are the method's.
    ``steps`` (a whole number, at least 1; both stop earlier at ``budget`` seconds or at ``error``): splatting makes
    that many frames, the coefficient count doubling from one to the next (it takes ``steps`` or ``budget``, one
    of them; 8 steps with ``error`` alone); ray tracing keeps the last ``steps`` frames of its schedule, full
    detail on images halving in size down to a least side, then the full image (default: every one; an image too
    small for that many gives all it allows, with a :class:`~clwave.ClwaveWarning`).  ``error``: stop at the first
    frame whose estimated relative RMS error is at most that."""
    if method == "splat":
        run = splat_progressive
    elif method == "raytrace":
        run = raytrace_progressive
    else:
        raise InputError(f"method={method!r} must be 'splat' or 'raytrace'")
    return run(wv, camera, steps=steps, budget=budget, device=device, error=error, **options)


def raytrace_progressive(wv, camera, steps=None, budget=None, device=None, *, error=None, tolerance=1e-3,
                         lights=None, shading=True, absorption=True, device_memory=None,
                         tracer: RayTracer | None = None, transfer_function=None, clip=None):
    """Yield :class:`~clwave.raytrace.progressive.RaytraceFrame` s from cheap to exact; the last is bit for bit the
    image of ``RayTracer.render`` (full detail, the full image, ``tolerance``).

    Parameters
    ----------
    steps : int >= 1, optional
        The last ``steps`` frames of the schedule (default every one: images 2^k, ..., 8, 4 times smaller per side,
        then the full image; docs/raytracing.md §9).
    budget : float > 0, optional
        Seconds: stop before a frame expected to end beyond the budget (from the last frame's time per pixel);
        the first frame is always made.
    error : float in (0, 1), optional
        Stop at the first frame whose estimated relative RMS error is at most this.
    tolerance, lights, shading, absorption, transfer_function, clip :
        As for :func:`clwave.raytrace`; every frame uses them.
    tracer : RayTracer, optional
        Without it, calls on the same model and device share one with :func:`clwave.raytrace`.
    """
    if tracer is None:
        tracer = shared_tracer(wv, device, device_memory=device_memory)
    options = dict(tolerance=tolerance, lights=lights, shading=shading, absorption=absorption,
                   transfer_function=transfer_function, clip=clip)
    return tracer.refine(camera, **options, steps=steps, budget=budget, error=error)
