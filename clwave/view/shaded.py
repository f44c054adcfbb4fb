"""The viewer's shaded frames (docs/viewer.md §2): emission-absorption ray tracing with one reused
:class:`~clwave.RayTracer`, made off the render thread on the first shaded view.

The model is traced with every detail's bricks (``lod=True``, docs/raytracing.md §8): while dragging, a reduced
image at a coarse detail and a looser tolerance, paced to the measured time; when still,
:meth:`~clwave.RayTracer.refine` (§9), full detail on reduced images to the full size at the tolerance, each
frame with its error estimate.  A scalar model is classified while rendering by the tab's transfer function
(``transfer_function=``, §10, at every detail): a preset, its window moved and widened, its opacity scaled, or
points of its own, from the page's editor.
"""

from __future__ import annotations

import threading
import time
import weakref
from dataclasses import dataclass

import numpy as np

from ..io.result import RenderResult
from ..model.transfer import TransferFunction
from ..threads import Abandoned
from .frames import NO_COEFFICIENTS, NOTHING_VISIBLE, ZERO_FOG, Frame, Source, ViewState, check_tolerance

#: shaded frames while dragging aim at this many seconds of ray tracing (5 frames a second with the round trip)
DRAG_SECONDS = 0.12
#: frames while dragging: the tolerance times this
LOOSEN = 10.0
#: frames while dragging, cheapest first: (image scale, detail)
DRAG_STEPS = ((0.0625, 3), (0.125, 2), (0.1875, 2), (0.25, 1), (0.375, 1), (0.5, 1), (0.5, 0))
#: bins of the histogram of a scalar model's values behind the page's transfer-function editor
HISTOGRAM_BINS = 64


@dataclass
class ShadedPace:
    """One tab's shaded pacing: the index of its next drag frame in the source's steps."""

    step: int


class ShadedSource(Source):
    """Shaded frames of an RGBA model (level of detail) or a scalar one (a transfer function at render time).

    ``path``: the model is that ``.clw`` file, traced in stages (:class:`~clwave.raytrace.staged.StagedTracer`,
    docs/raytracing.md §8): frames of its coarse stage at once, of the whole file's tracer once it is set up in the
    background, when ``upgraded(mode, failure)`` (a callable, from that thread) is called: made from the model the
    viewer holds (``wv``, or ``whole()`` where given), not read again.  ``whole``: ``wv`` is a prefix of the model,
    and this callable gives the whole one (read meanwhile for the X-ray views), which the tracer waits for.
    ``coarse``: a callable giving the coarse stage's reading of the file (``PrefixFirst.coarse``, read before the rest).
    ``transfer_function``: a scalar model's starting function (None: its own, or grey).  ``device_memory``: the
    tracer's cap (both stages of a file's together)."""

    mode = "shaded"

    def __init__(self, wv, size, tolerance, device=None, path=None, whole=None, coarse=None, upgraded=None,
                 transfer_function=None, device_memory=None):
        super().__init__(wv, size)
        self.tolerance, self.device, self.tracer = check_tolerance(tolerance), device, None
        self.device_memory = device_memory
        self.path, self.whole, self.staged, self.upgraded, self._watch = path, whole, None, upgraded, None
        self.coarse, self.read = coarse, whole is None  # read: the whole model is in (the page's status line)
        self.scalar = wv.channels == 1
        self.steps = [(s, d) for s, d in DRAG_STEPS if d <= wv.levels]
        self.capabilities = dict(tf=self.scalar, background=True, shading=True)
        # where a scalar model's classification starts (the page's editor too): the one given, the model's, or grey
        own = wv.transfer_function
        self.start_tf = None if not self.scalar else transfer_function or (
            TransferFunction.from_dict(own) if own else TransferFunction.preset("grey"))
        #: a transfer function was chosen (given, or the model's own: a volume classified with it): the page opens in
        #: this mode, where the user's function shows (docs/viewer.md §3)
        self.chosen = transfer_function is not None or bool(own)
        self._tf = (None, None, None)  # the last (key, transfer function, window): the tracer reuses its table
        self._histogram = (None, None)  # (the tracer's weak reference, its histogram)

    def ready(self) -> bool:
        return self.tracer is not None or self.staged is not None

    def pacing(self) -> ShadedPace:
        return ShadedPace(len(self.steps) // 2)

    def prepare(self):
        """The ray tracer (of a file: its coarse stage), and its kernels built by a small image (on the build
        thread, not the render thread); nothing once the viewer stops (:class:`Abandoned` at the set-up's or the
        launches' next checkpoint: no tracer, and no error for a Future nobody reads)."""
        try:
            self._prepare()
        except Abandoned:
            pass

    def _prepare(self):
        from ..model.camera import Camera
        from ..raytrace.staged import StagedTracer
        from ..raytrace.tracer import RayTracer

        warm = dict(transfer_function=self.start_tf) if self.scalar else {}
        if self.path is not None and self.staged is None:
            staged = StagedTracer(RayTracer, self.path, device=self.device, device_memory=self.device_memory, lod=True,
                                  whole=self._whole_model,
                                  coarse=None if self.coarse is None else self.coarse())
            # the coarse stage's kernels; the whole file's set-up starts with the page's first frame (staged.render),
            # so that its reading does not delay that frame
            staged.coarse.render(Camera(30.0, 20.0, 16), tolerance=self.tolerance * LOOSEN,
                                 detail=staged.coarse_detail, **warm)
            self.staged = staged
            self._watch = threading.Thread(target=self._upgrade, name="clwave-view-full-stage", daemon=True)
        elif self.path is None and self.tracer is None:
            if self.whole is not None:  # a part of a file (keep=): the tracer waits for all of that part
                self.wv = self.whole()
            # a model held in memory: the build stops at its next slab once the viewer stops (the build thread's
            # threads.stop_on event, set by the server's stop)
            tracer = RayTracer(self.wv, device=self.device, device_memory=self.device_memory, lod=True)
            tracer.render(Camera(30.0, 20.0, 16), tolerance=self.tolerance * LOOSEN, **warm)
            self.tracer = tracer

    def stop(self):
        """The viewer stopping: a file's full stage still being set up, on its own thread, is given up (it stops after
        the read, or at the slab or band of its set-up under way); a tracer of a model held in memory, built on the
        server's build thread, stops by that thread's stop (:func:`clwave.threads.stop_on`)."""
        if self.staged is not None:
            self.staged.abandon()

    def start_full_stage(self):
        """On the render thread: a file's full stage set up where no frame has started it (a save or a command asked
        for before any shaded frame, export.resolve: theirs is the full stage's tracer)."""
        if self.staged is not None and self.tracer is None:
            self.staged.start()
            self._watch_full_stage()

    def _watch_full_stage(self):
        """Once a coarse frame has started the whole file's set-up: a thread that waits for it (:meth:`_upgrade`)."""
        if self._watch.ident is None:
            self._watch.start()

    def _upgrade(self):
        """Wait for a file's full stage, then trace with it (its set-up failing: the coarse stage stays); tell
        ``upgraded`` either way."""
        try:
            self.tracer = self.staged.wait()
        except Exception as exc:  # noqa: BLE001  (the coarse stage goes on serving)
            failure = exc
        else:
            failure = None
        if self.upgraded is not None:
            self.upgraded(self.mode, failure)

    def start_figures(self) -> dict | None:
        """The page's editor's start: the starting transfer function's name and window (``"auto"``: the pool's
        percentiles, known once the tracer is made; a function without one, its points' span); None for an RGBA
        model."""
        if not self.scalar:
            return None
        window = self.start_tf.window
        return dict(name=self.start_tf.name, window=window if window == "auto" else _span(self.start_tf, window))

    def transfer_function(self, spec, tracer) -> tuple:
        """``(transfer function, its window in the input's units)`` of a tab's ``(preset, centre, width, opacity)``: the
        preset's points (preset None: the starting function's) with their opacity times ``opacity``, under its window
        (the pool's percentiles where "auto", the points' span where it has none: points in the input's units) widened
        ``width`` times and moved by ``centre`` of its width; spec None, or the starting function unchanged, is the
        starting function itself (its window as given, not recomputed); an "auto" window is the pool of ``tracer``,
        the one that renders the frame (the whole file's once it is in).  A spec that is a TransferFunction (the
        editor's points, in the input's units) is itself.  Presets and points take the starting function's opacity
        unit (``--opacity-unit``, a file's function's).  ``(None, None)`` for an RGBA model."""
        if not self.scalar:
            return None, None
        key = (spec, weakref.ref(tracer))  # not id(): a tracer let go may leave its id to the next
        if self._tf[0] != key:
            unit = self.start_tf.opacity_unit  # the tab's opacities are per the starting function's unit
            if isinstance(spec, TransferFunction):  # the editor's points
                tf, change = spec.under(opacity_unit=unit), [0.0, 1.0, 1.0]
            else:
                name, *change = (None, 0.0, 1.0, 1.0) if spec is None else spec
                tf = self.start_tf if name is None else TransferFunction.preset(name, opacity_unit=unit)
            lo, hi = window = _span(tf, tracer.scalar.window(tf))
            if change != [0.0, 1.0, 1.0]:
                centre, width, opacity = change
                mid, half = (lo + hi) / 2 + centre * (hi - lo), (hi - lo) * width / 2
                points = tf.points.copy()
                if tf.window is None:  # points in the input's units: on the normalised axis of their span first
                    points[:, 0] = (points[:, 0] - lo) / (hi - lo)
                points[:, 4] *= opacity
                window = (mid - half, mid + half)
                tf = TransferFunction(points, window=window, name=tf.name, opacity_unit=tf.opacity_unit)
            self._tf = (key, tf, [float(v) for v in window])
        return self._tf[1:]

    def _stage(self, tracer):
        """The tracer that renders now: ``tracer`` (the whole model's), else a file's coarse stage."""
        return tracer or self.staged.coarse or self.staged.full

    def histogram(self) -> dict | None:
        """The values behind the page's transfer-function editor: a histogram (:data:`HISTOGRAM_BINS`) of the field
        values that the tracer rendering now takes an "auto" window from (``ScalarRange.sample``, docs/raytracing.md
        §10; at most 2^16), made once a tracer: over the input's range, clamped to it as the classification sees them
        (``input`` true), else (a .clw of before the range was kept) from the least value to the greatest; ``field``:
        the sample's least and greatest (a model rings past its input's range).  None for an RGBA model, or bricks in a
        scratch file (no sample)."""
        stage = self._stage(self.tracer) if self.scalar and self.ready() else None
        sample = None if stage is None else stage.scalar.sample
        if sample is None:
            return None
        if self._histogram[0] is None or self._histogram[0]() is not stage:
            known, shift = stage.scalar.value_range, stage.scalar.subtracted  # the input's range: what is classified
            counts, edges = np.histogram(sample if known is None else np.clip(sample, *known), bins=HISTOGRAM_BINS,
                                         range=known)
            edges += shift  # in the input's units, as the editor's window and points
            self._histogram = (weakref.ref(stage), dict(range=[float(edges[0]), float(edges[-1])],
                                                        counts=counts.tolist(), input=known is not None,
                                                        field=[float(sample.min()) + shift,
                                                               float(sample.max()) + shift]))
        return self._histogram[1]

    def frames(self, state: ViewState, pace: ShadedPace):
        start = time.perf_counter()
        tracer = self.tracer  # None while a file's whole tracer is being set up: its coarse stage
        # a tracer warns once about each thing (a script's many renders); here each view is told (the page's note)
        for t in {t for t in (tracer, self.staged and self.staged.coarse, self.staged and self.staged.full) if t}:
            t.told.clear()
        # a scalar model's: its window and points in the input's units, figures of each frame (the page's editor
        # draws them)
        options, classified = dict(shading=state.shading, clip=state.clipping()), {}
        if self.scalar:
            # the tracer read once: another thread sets self.tracer when the whole file's is ready
            tf, window = self.transfer_function(state.tf, self._stage(tracer))
            values = tf.data_points(None if tf.window is None else window)
            options["transfer_function"] = tf
            classified = dict(tf_window=window, tf_points=np.column_stack([values, tf.points[:, 1:]]).tolist())
        if state.moving:
            scale, detail = self.steps[pace.step]
            if tracer is None:
                result, detail = self.staged.render(self.camera(state, scale), tolerance=self.tolerance * LOOSEN,
                                                    **options), self.wv.levels
                self._watch_full_stage()
            else:
                result = tracer.render(self.camera(state, scale), tolerance=self.tolerance * LOOSEN, detail=detail,
                                       **options)
            seconds = time.perf_counter() - start
            self._pace(pace, seconds)
            yield self._shaded(state, result, False, dict(tolerance=self.tolerance * LOOSEN, detail=detail,
                                                          error=None, **classified), seconds, start)
            return
        if tracer is None:
            yield from self._coarse(state, options, classified, start)
            return
        last = start
        for f in self.tracer.refine(self.camera(state), tolerance=self.tolerance, **options):
            final = (f.detail, f.reduction) == (0, 1)
            now = time.perf_counter()
            yield self._shaded(state, f.result(), final, dict(tolerance=self.tolerance, detail=f.detail,
                                                              reduction=f.reduction,
                                                              error=_number(f.estimated_relative_rms_error),
                                                              **classified),
                               now - last, start)
            last = time.perf_counter()

    def _coarse(self, state, options, classified, start):
        """A still view while a file's whole tracer is set up: its coarse stage on a quarter and on the whole
        image, neither final (the view is traced again when the whole file is in); once that set-up has failed, the
        coarse stage is the model served from then on (as the X-ray views' prefix): the whole image final.  Their
        ``waiting`` figure says what the page waits for: "reading" the rest of the file, "set-up" of the whole
        file's tracer, None (served)."""
        for reduction in (4, 1):
            stage = time.perf_counter()
            result = self.staged.render(self.camera(state, 1 / reduction), tolerance=self.tolerance, **options)
            self._watch_full_stage()
            served = self.staged.failed  # read after the render, which then drew the coarse stage
            waiting = None if served else "set-up" if self.read else "reading"
            yield self._shaded(state, result, served and reduction == 1,
                               dict(tolerance=self.tolerance, detail=self.wv.levels, reduction=reduction, error=None,
                                    waiting=waiting, **classified),
                               time.perf_counter() - stage, start)

    def _whole_model(self):
        """The whole model for the full stage's set-up (on its thread): the one held, not read again, or the rest of
        the file read for the X-ray views, waited for."""
        if self.whole is None:
            return self.wv
        wv = self.whole()
        self.read = True
        return wv

    def _pace(self, pace: ShadedPace, seconds):
        """The tab's next drag frame a step cheaper when this one took longer than :data:`DRAG_SECONDS`, a step
        finer when it took under a third of that."""
        if seconds > DRAG_SECONDS and pace.step > 0:
            pace.step -= 1
        elif seconds < DRAG_SECONDS / 3 and pace.step < len(self.steps) - 1:
            pace.step += 1

    def _shaded(self, state, result: RenderResult, final, figures, seconds, start) -> Frame:
        picture = result.to_uint8(background=(state.background,) * 3)
        # the page's status line says why an image is blank, or what it shows of a model without coefficients
        if not self.wv.kept:
            note = ZERO_FOG if result.image[..., 3].any() else NO_COEFFICIENTS
        else:
            note = NOTHING_VISIBLE if result.meta.get("nothing_visible") else None
        return self._frame(state, picture, final or not state.moving,
                           dict(figures, final=final, seconds=seconds,
                                error_kind="relative RMS against the model's final image, estimated from the last step",
                                **({} if note is None else dict(note=note))), start)


def _span(tf: TransferFunction, window) -> list:
    """``window`` (lo, hi) in the input's units as a list, or for ``tf`` without one (window None: its points in the
    input's units) the span of its points."""
    return [float(v) for v in (tf.points[[0, -1], 0] if window is None else window)]


def _number(x):
    """A figure for JSON: None where it is not a finite number (a first frame's estimate)."""
    return float(x) if x is not None and np.isfinite(x) else None
