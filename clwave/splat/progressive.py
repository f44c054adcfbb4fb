"""Progressive refinement by wavelet splatting (paper §5.2, Fig. 15).

Coefficients are splatted in order of importance into one framebuffer, so frame
k adds to frame k - 1 and never restarts.  Each frame reports the time so far,
the fraction of coefficients, the energy captured, and its RMS and maximum error
against the final image (the image of every coefficient).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..model.camera import Camera
from ..errors import InputError
from ..io.result import RenderResult
from .renderer import SplatRenderer, shared_renderer
from ..model.wavelet import WaveletVolume


class _FinalImage:
    """The all-coefficient image, known at the end of a complete run or rendered on demand."""

    def __init__(self, renderer: SplatRenderer, camera: Camera):
        self.renderer, self.camera, self.image = renderer, camera, None

    def get(self) -> np.ndarray:
        if self.image is None:
            acc = self.renderer.begin(self.camera)
            acc.splat(0, self.renderer.count)
            self.image = acc.image()
        return self.image


@dataclass
class ProgressiveFrame:
    """One refinement step: ``image`` (H, W, C) after ``coefficients`` splats, ``fraction`` of the
    model's kept coefficients and ``voxel_fraction`` of its voxels.

    Errors are against the final image (every kept coefficient): absolute, and relative to the
    final image's largest magnitude.  :meth:`save` writes the frame as :meth:`RenderResult.save` does.
    """

    index: int
    image: np.ndarray
    coefficients: int
    fraction: float
    voxel_fraction: float
    energy: float
    seconds: float
    meta: dict = field(default_factory=dict)
    _final: _FinalImage | None = field(default=None, repr=False)

    def final_image(self) -> np.ndarray:
        """The image of every coefficient, which the frames converge to."""
        return self._final.get()

    def error_image(self) -> np.ndarray:
        """Final image minus this frame (what is still missing)."""
        return self.final_image() - self.image

    @property
    def rms_error(self) -> float:
        return float(np.sqrt(np.mean(self.error_image() ** 2)))

    @property
    def max_error(self) -> float:
        return float(np.max(np.abs(self.error_image())))

    @property
    def relative_rms_error(self) -> float:
        """RMS error over the final image's largest magnitude."""
        return self.rms_error / self._final_peak()

    @property
    def relative_max_error(self) -> float:
        return self.max_error / self._final_peak()

    def _final_peak(self) -> float:
        return max(float(np.max(np.abs(self.final_image()))), np.finfo(np.float32).tiny)

    def figures(self) -> dict:
        """The per-frame figures as plain numbers (JSON-ready)."""
        error, peak = self.error_image(), self._final_peak()
        rms, top = float(np.sqrt(np.mean(error ** 2))), float(np.max(np.abs(error)))
        return dict(index=self.index, coefficients=self.coefficients, fraction=self.fraction,
                    voxel_fraction=self.voxel_fraction, energy=self.energy, seconds=self.seconds,
                    rms_error=rms, max_error=top, relative_rms_error=rms / peak, relative_max_error=top / peak)

    def result(self) -> RenderResult:
        """The frame as a :class:`~clwave.RenderResult` (its image and meta)."""
        return RenderResult(self.image, self.meta)

    def save(self, path, **options) -> Path:
        """Write the frame: ``.png``, ``.npy`` or ``.json``, options as :meth:`RenderResult.save`."""
        return self.result().save(path, **options)


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


def progressive(wv: WaveletVolume, camera: Camera, steps=None, budget=None, device=None, *,
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
    omega_s, sampling, coarse, device_memory :
        As for :class:`clwave.SplatRenderer` (coefficients beyond the device budget stream in chunks;
        a frame's passes end at chunk boundaries too).
    """
    check_schedule(steps, budget)
    r = renderer or shared_renderer(wv, device, omega_s, sampling, coarse, device_memory)
    return _frames(r, camera, steps, budget)


def _frames(r: SplatRenderer, camera: Camera, steps, budget):
    total = r.count
    final = _FinalImage(r, camera)
    energy = r.energy
    start = time.perf_counter()
    acc = r.begin(camera)
    counts = schedule(total, int(steps) if steps is not None else 8)
    done = 0
    for index, count in enumerate(counts):
        if budget is not None and index > 0:
            elapsed = time.perf_counter() - start
            per_coefficient = elapsed / max(done, 1)
            if elapsed + per_coefficient * (count - done) > budget:
                return
        acc.splat(done, count - done)
        done = count
        image = acc.image()
        if done == total:
            final.image = image
        yield ProgressiveFrame(index, image, done, done / max(total, 1), done / r.wv.n_voxels,
                               float(energy[done - 1] / energy[-1]) if done and energy[-1] > 0 else 0.0,
                               time.perf_counter() - start,
                               acc.meta(time.perf_counter() - start), final)
