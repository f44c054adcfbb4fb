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
from ..errors import InputError
from ..frames import FinalImage, Frame, check_error, reached
from .renderer import SplatRenderer, shared_renderer
from .spectral import centred_fourier
from .tables import MAX_LEVELS
from ..model.wavelet import WaveletVolume


@dataclass(kw_only=True)
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
    if steps is not None and (isinstance(steps, bool) or int(steps) != steps or not 1 <= steps <= MAX_STEPS):
        raise InputError(f"steps={steps!r} must be a whole number from 1 to {MAX_STEPS} (each frame doubles "
                         f"the coefficients)", cli=f"--steps {steps} must be a whole number from 1 to {MAX_STEPS}")
    if budget is not None and not (np.isfinite(budget) and budget > 0):
        raise InputError(f"budget={budget!r} must be a positive number of seconds",
                         cli=f"--budget {budget:g} must be a positive number of seconds")


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
        last frame holds every coefficient (it equals :func:`clwave.splat`).
    budget : float > 0
        Seconds: keep doubling while the next step is expected to finish within the
        budget (estimated from the throughput so far); the last frame yielded is the
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
    done, estimate = counts[0] // 2, SplatEstimate(r, acc.view)  # the first frame's estimate: a step from half
    if done:                                                       # its coefficients (from the empty image)
        acc.splat(0, done)
    estimate.add(acc.image(), done)
    for index, count in enumerate(counts):
        if budget is not None and index > 0:
            elapsed = time.perf_counter() - start
            per_coefficient = elapsed / max(done, 1)
            if elapsed + per_coefficient * (count - done) > budget:
                return
        acc.splat(done, count - done)
        done = count
        image = acc.image()
        rms, top = estimate.add(image, done)
        if done == total:
            final.image, rms, top = image, 0.0, 0.0
        frame = ProgressiveFrame(index=index, image=image, seconds=time.perf_counter() - start,
                                 estimated_relative_rms_error=rms, estimated_relative_max_error=top,
                                 meta=acc.meta(time.perf_counter() - start), _final=final, coefficients=done,
                                 fraction=done / max(total, 1), voxel_fraction=done / r.wv.n_voxels,
                                 energy=float(energy[done - 1] / energy[-1]) if done and energy[-1] > 0 else 0.0)
        yield frame
        if reached(frame, error):
            return


SLICE_POINTS = 64  # per side of the slice grid integrating a band's footprint energy (docs/splatting.md §5), times
#                   the spacings' largest ratio (the finest spectral lobe is 2 pi / max(d) wide), up to 8 times


def band_energies(wavelet, spacing, view) -> np.ndarray:
    """Image energy of a unit coefficient of each band code ``level * 8 + code`` (in world units at unit spacing;
    otherwise up to one factor of the volume).

    Splatting is linear and a footprint is the projection of its function, so by the slice theorem a unit
    coefficient of band (m, key) draws the energy ``2^m I_key``, with ``I_key = ∫∫ prod_a |G_a(d_a (U u_a +
    V v_a))|^2 dU dV`` over the slice plane (G: :func:`~clwave.splat.spectral.centred_fourier`, d: the spacing);
    psi along the ray draws nothing.  A perspective view takes its axis (its obliquity is left to the
    calibration of :class:`SplatEstimate`).
    """
    d_xyz = np.asarray(spacing, float)[::-1]
    reach = 16.0 * np.pi / float(np.min(d_xyz))  # |G|^2 is below 1e-6 of its peak beyond 16 pi / d
    grid = np.linspace(-reach, reach, int(SLICE_POINTS * min(8.0, np.ceil(np.max(d_xyz) / np.min(d_xyz)))))
    U, V = np.meshgrid(grid, grid)
    power = [{letter: np.abs(centred_fourier(wavelet, letter, d_xyz[a] * (U * view.u[a] + V * view.v[a]))) ** 2
              for letter in "ad"} for a in range(3)]
    integral = np.array([np.sum(power[0]["ad"[code & 1]] * power[1]["ad"[code >> 1 & 1]]
                                * power[2]["ad"[code >> 2 & 1]]) for code in range(8)])
    integral *= (grid[1] - grid[0]) ** 2 / (2.0 * np.pi) ** 2  # Parseval: the 2-D energy
    return np.outer(2.0 ** np.arange(MAX_LEVELS), integral).reshape(-1)


class SplatEstimate:
    """The error of each splatting frame against the final image, from what is still to splat (docs/splatting.md §5).

    The error of frame k is exactly the image of the coefficients not yet splatted.  Each coefficient's image
    energy is predicted as ``c^2`` times its band's (:func:`band_energies`), cumulative in importance order; the
    step that made the frame calibrates the prediction (measured over predicted energy: overlaps of footprints,
    the view's scale), so the rest's RMS is ``sqrt(kappa R_k / values)``, R_k the predicted energy of the rest.
    The maximum scales the step's by the same ``sqrt(R_k / S_k)`` (a heuristic: the rest keeps the step's ratio
    of maximum to RMS).  Both over the frame's largest magnitude, times margins calibrated on training volumes
    (the 5 % quantile of estimate over measured error to 1; docs/splatting.md §5 has the held-out figures).
    """

    RMS_MARGIN, MAX_MARGIN = 1.8, 1.5

    def __init__(self, r: SplatRenderer, view):
        self.prefix = []
        for g, group in zip(r.wv.groups, r.groups):
            table = group["table"]
            weight = band_energies(g.wavelet, r.wv.spacing, view)[table.level.astype(np.int64) * 8 + table.key_code]
            c2 = np.sum(np.asarray(table.values, np.float64) ** 2, axis=1)
            self.prefix.append(np.concatenate([[0.0], np.cumsum(weight * c2)]))
        self.whole = sum(float(p[-1]) for p in self.prefix)
        self.last, self.done, self.kappa, self.top_ratio = None, 0, None, None

    def predicted(self, count: int) -> float:
        """Predicted image energy of the first ``count`` coefficients of every group."""
        return sum(float(p[min(count, len(p) - 1)]) for p in self.prefix)

    def add(self, image: np.ndarray, done: int) -> tuple:
        """(relative RMS, relative max) estimated for ``image`` after ``done`` coefficients; (nan, nan) for the
        first image, which sets the start of the first step."""
        last, self.last = self.last, image
        before, self.done = self.done, done
        if last is None:
            return float("nan"), float("nan")
        step = image - last
        peak = max(float(np.max(np.abs(image), initial=0.0)), np.finfo(np.float32).tiny)
        measured, top = float(np.sum(step.astype(np.float64) ** 2)), float(np.max(np.abs(step), initial=0.0))
        made, rest = self.predicted(done) - self.predicted(before), self.whole - self.predicted(done)
        if made > 0 and measured > 0:
            self.kappa, self.top_ratio = measured / made, top / np.sqrt(made)
        if self.kappa is None:  # nothing measured yet: the step alone
            return float(np.sqrt(measured / step.size)) / peak, top / peak
        rms = np.sqrt(self.kappa * rest / step.size)
        return self.RMS_MARGIN * float(rms) / peak, self.MAX_MARGIN * float(self.top_ratio * np.sqrt(rest)) / peak
