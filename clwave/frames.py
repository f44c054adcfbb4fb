"""Progressive frames, whatever the method (docs/raytracing.md §9, docs/splatting.md §5): :class:`Frame` is what
splatting (:mod:`clwave.splat.progressive`) and ray tracing (:mod:`clwave.raytrace.progressive`) yield, each with
an estimate of its error against the final image made without the final image (splatting's from the coefficients
still to splat, :class:`clwave.splat.estimate.SplatEstimate`; ray tracing's from the step between its
full-detail frames, :class:`ErrorEstimate`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import InputError, finite_number
from .io.result import RenderResult


def root_mean_square(image) -> float:
    """The root mean square of ``image``, its squares summed in float64: a float32 image's squares may each be
    finite and their sum not (line integrals up to 1.8e19, docs/coordinates.md §3)."""
    return float(np.sqrt(np.mean(np.square(image, dtype=np.float64))))


class ErrorEstimate:
    """The error of each frame against the final one, from the step that made it (docs/raytracing.md §9).

    With ``e_k`` the error of frame k and ``d_k = f_k - f_{k-1}`` its step, ``e_{k-1} - e_k <= |d_k| <=
    e_{k-1} + e_k``; where each frame halves to thirds the error (``e_k = rho e_{k-1}``, 1/3 <= rho <= 1/2), the
    estimate ``|d_k|`` is between ``e_k`` and ``4 e_k``.  RMS and max alike, both over the largest magnitude
    of the frame (the final image's, as far as the frame knows it).
    """

    def __init__(self):
        self.last = None

    def add(self, image: np.ndarray) -> tuple:
        """(relative RMS, relative max) estimated for ``image``, the next frame; (nan, nan) for a first frame
        with nothing before it, (1, 1) for an empty one (the whole final image may be missing)."""
        last, self.last = self.last, image
        if last is None:
            return float("nan"), float("nan")
        peak = float(np.max(np.abs(image), initial=0.0))
        if peak == 0:  # a frame that sees nothing: its error is the final image itself (relative max 1, RMS at most 1)
            return 1.0, 1.0
        step = image - last
        return root_mean_square(step) / peak, float(np.max(np.abs(step), initial=0.0)) / peak


class FinalImage:
    """The final image of a run, known at its end or rendered on demand by ``render()``."""

    def __init__(self, render):
        self.render, self.image = render, None

    def get(self) -> np.ndarray:
        if self.image is None:
            self.image = self.render()
        return self.image


@dataclass
class Frame:
    """One refinement step: ``image`` (H, W, C) at the full size, after ``seconds``; its estimated error against
    the final image (``estimated_relative_rms_error``, ``estimated_relative_max_error``: relative to the largest
    value, made without the final image; 0 for the final frame) and, on demand, its measured error.  :meth:`save`
    writes the frame as :meth:`RenderResult.save` does."""

    index: int
    image: np.ndarray
    seconds: float
    estimated_relative_rms_error: float
    estimated_relative_max_error: float
    meta: dict = field(default_factory=dict)
    _final: FinalImage | None = field(default=None, repr=False)

    def final_image(self) -> np.ndarray:
        """The image the frames converge to."""
        return self._final.get()

    def error_image(self) -> np.ndarray:
        """Final image minus this frame (what is still missing)."""
        return self.final_image() - self.image

    @property
    def rms_error(self) -> float:
        return root_mean_square(self.error_image())

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

    def own_figures(self) -> dict:
        """The figures of the method (subclasses)."""
        return {}

    def figures(self) -> dict:
        """The per-frame figures as plain numbers (JSON-ready), measured errors against the final image."""
        error, peak = self.error_image(), self._final_peak()
        rms_error, top = root_mean_square(error), float(np.max(np.abs(error)))
        return dict(index=self.index, **self.own_figures(), seconds=self.seconds, rms_error=rms_error, max_error=top,
                    relative_rms_error=rms_error / peak, relative_max_error=top / peak,
                    estimated_relative_rms_error=self.estimated_relative_rms_error,
                    estimated_relative_max_error=self.estimated_relative_max_error)

    def result(self) -> RenderResult:
        """The frame as a :class:`~clwave.RenderResult` (its image and meta)."""
        return RenderResult(self.image, self.meta)

    def save(self, path, **options) -> Path:
        """Write the frame: ``.png``, ``.tif``, ``.npy`` or ``.json``, options as :meth:`RenderResult.save`."""
        return self.result().save(path, **options)


def check_error(error):
    """``error`` (None, or a relative error in (0, 1)) checked before any work."""
    if error is not None and not 0 < finite_number(error, "error") < 1:
        raise InputError(f"error={error!r} must be a relative error between 0 and 1",
                         cli=f"--error {error} must be a relative error between 0 and 1")


def check_budget(budget):
    """``budget`` (None, or seconds > 0) checked before any work."""
    if budget is not None and not finite_number(budget, "budget") > 0:
        raise InputError(f"budget={budget!r} must be a positive number of seconds",
                         cli=f"--budget {budget:g} must be a positive number of seconds")


def reached(frame: Frame, error) -> bool:
    """Whether ``frame`` is good enough for ``error=``: its estimated relative RMS error is at most that."""
    return error is not None and frame.estimated_relative_rms_error <= error
