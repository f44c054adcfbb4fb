"""Progressive refinement by wavelet splatting (paper §5.2, Fig. 15).

Coefficients are splatted in order of importance into one framebuffer, so frame
k adds to frame k - 1 and never restarts.  Each frame reports the time so far,
the fraction of coefficients, the energy captured, its estimated error against the final
image (:class:`SplatEstimate`, from the coefficients still to splat) and, on demand, the measured one.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..model.camera import Camera
from ..errors import ClwaveWarning, InputError, warn_outside, whole_number
from ..frames import FinalImage, Frame, check_budget, check_error, reached
from .renderer import SplatRenderer, shared_renderer
from .estimate import SplatEstimate
from ..model.wavelet import WaveletVolume


@dataclass(kw_only=True, repr=False)
class ProgressiveFrame(Frame):
    """One refinement step: ``image`` (H, W, C) after ``coefficients`` splats, ``fraction`` of the
    model's kept coefficients and ``voxel_fraction`` of its voxels; errors as :class:`~clwave.frames.Frame`
    (the final image: every kept coefficient)."""

    coefficients: int
    fraction: float
    voxel_fraction: float
    energy: float

    def own_figures(self) -> dict:
        return dict(coefficients=self.coefficients, fraction=self.fraction, voxel_fraction=self.voxel_fraction,
                    energy=self.energy)


MAX_STEPS = 64  # frames double the coefficients: 2^63 are more than any model holds


def check_schedule(steps, budget):
    """Exactly one of ``steps`` (1 to :data:`MAX_STEPS` frames) and ``budget`` (seconds > 0), checked before
    any work (each message also in the command line's words)."""
    if (steps is None) == (budget is None):
        raise InputError("give exactly one of steps= (number of frames) or budget= (seconds)",
                         cli="give one of --steps N or --budget SECONDS")
    if steps is not None and (not whole_number(steps) or not 1 <= steps <= MAX_STEPS):
        raise InputError(f"steps={steps!r} must be a whole number from 1 to {MAX_STEPS} (each frame doubles "
                         f"the coefficients)", cli=f"--steps {steps} must be a whole number from 1 to {MAX_STEPS}")
    check_budget(budget)


def schedule(total: int, steps: int) -> list:
    """Coefficient counts of ``steps`` frames, doubling up to ``total`` (the last frame has all)."""
    counts = [int(np.ceil(total / 2.0 ** (steps - 1 - i))) for i in range(steps)]
    return sorted(set(max(1, c) for c in counts)) if total else [0]


def progressive(wv: WaveletVolume, camera: Camera, steps=None, budget=None, device=None, *, error=None,
                omega_s=None, sampling="auto", coarse=None, device_memory=None, renderer: SplatRenderer | None = None):
    """Yield :class:`ProgressiveFrame` s, coarse to fine, into one framebuffer.

    Parameters
    ----------
    steps : int >= 1
        Number of frames; the coefficient count doubles from frame to frame and the
        last frame holds every coefficient (it equals :func:`clwave.splat` to float32 rounding, docs/splatting.md §5).
    budget : float > 0
        Seconds: keep doubling while the next step is expected to finish within the
        budget (from the last frame's own time per coefficient, set-up apart); the last frame yielded is the
        last one completed.  The first frame is always made.
    error : float in (0, 1)
        Stop at the first frame whose estimated relative RMS error is at most this (with ``steps``, or
        ``budget``, or alone: then the schedule of 8 steps).
    omega_s, sampling, coarse, device_memory :
        As for :class:`clwave.SplatRenderer` (coefficients beyond the device budget stream in chunks;
        a frame's passes end at chunk boundaries too).
    """
    check_error(error)
    if steps is None and budget is None and error is not None:
        steps = 8
    check_schedule(steps, budget)
    r = renderer or shared_renderer(wv, device, omega_s, sampling, coarse, device_memory)
    return _frames(r, camera, steps, budget, error)


def _frames(r: SplatRenderer, camera: Camera, steps, budget, error):
    total = r.count

    def render_final():
        acc = r.begin(camera)
        acc.splat(0, r.count)
        return acc.image()

    final = FinalImage(render_final)
    energy = r.energy
    start = time.perf_counter()
    acc = r.begin(camera)
    counts = schedule(total, int(steps) if steps is not None else 8)
    if steps is not None and len(counts) < steps:  # each frame doubles the coefficients, from one
        many = f"{len(counts)} progressive frame{'s' if len(counts) != 1 else ''}"
        line = f"a model of {total:,} coefficients allows {many}, each doubling them, not "
        warn_outside(ClwaveWarning(line + f"steps={steps}", cli=line + f"--steps {steps}"))
    done, estimate = 0, SplatEstimate(r, acc.view)
    per_coefficient = None  # the last frame's own seconds (splats, read-back, estimate) a coefficient it added
    for index, count in enumerate(counts):
        if budget is not None and per_coefficient is not None:
            if time.perf_counter() - start + per_coefficient * (count - done) > budget:
                return
        frame_start = time.perf_counter()
        acc.splat(done, count - done)
        added, done = count - done, count
        image = acc.image()
        if done == total:  # the final image: no error
            final.image, rms, top = image, 0.0, 0.0
        else:
            rms, top = estimate.add(image, done)
        per_coefficient = (time.perf_counter() - frame_start) / max(added, 1)
        frame = ProgressiveFrame(index=index, image=image, seconds=time.perf_counter() - start,
                                 estimated_relative_rms_error=rms, estimated_relative_max_error=top,
                                 meta=acc.meta(time.perf_counter() - start), _final=final, coefficients=done,
                                 fraction=done / max(total, 1), voxel_fraction=done / r.wv.n_voxels,
                                 energy=float(energy[done - 1] / energy[-1]) if done and energy[-1] > 0 else 0.0)
        yield frame
        if reached(frame, error):
            return
