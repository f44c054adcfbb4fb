"""The first image from a ``.clw`` file at once (docs/raytracing.md §8): :meth:`clwave.RayTracer.open` reads the
coarsest approximation alone (its own tier of the file, read first) and expands its bricks at the coarsest detail,
without the content mask (the file's occupancy of the approximation, a summary of it, gives its frames' estimate
the clamp's term); the whole model is read and set up in a background thread while the caller renders
the coarse stage.  :meth:`StagedTracer.refine` yields frames from the coarse stage until the full one is ready,
then the full stage's progressive frames (:mod:`clwave.raytrace.progressive`), the last bit for bit what the full
tracer's ``render`` gives.
"""

from __future__ import annotations

import atexit
import threading
import time

import numpy as np

from ..errors import InputError, caught_warnings, warn_outside
from ..frames import ErrorEstimate, FinalImage, check_error, reached, root_mean_square
from ..model.camera import Camera
from ..model.clip import check_clip
from ..model.tf_file import as_transfer_function
from ..model.conebeam import ConeBeam, check_camera
from ..model.transform import band_layout
from ..io.occupancy import mass_on_occupied
from ..io.summary import approximation_occupancy, detail_energy, detail_levels
from ..model.wavelet import ChannelGroup, WaveletVolume, importance_of
from .coarse_estimate import approximation_grid, detail_share, field_energy, line_energy, white_share
from ..threads import Abandoned
from .progressive import MIN_SIDE, RaytraceFrame, frames, schedule, upsample

#: a shaded coarse frame's max estimate takes the clamp's term times this: the clamp removes a haze that is
#: brightest at the silhouette, where the max error is (fitted on the 96 frames of docs/raytracing.md §9)
CLAMP_MAX_MARGIN = 1.4


class StagedTracer:
    """A ray tracer of a ``.clw`` file set up in two stages (made by :meth:`clwave.RayTracer.open`).

    ``coarse``: a :class:`~clwave.RayTracer` of the file's approximation alone (:func:`coarse_volume`; for mixed
    orders the bricks of the coarsest detail), its segments ``2^levels`` cells long, no content clamp (the
    coarse field blurs the content a little into empty space, docs/raytracing.md §8), ready when ``open``
    returns and let go (None) once the full stage is; ``full``: the tracer of the whole file
    (``RayTracer(WaveletVolume.open(path), lod=lod)``), made in a background thread started by the first coarse
    image (:meth:`start`, :attr:`ready`, :meth:`wait`); at the interpreter's exit a set-up still running is
    given up (:func:`_abandon`); ``whole``, where given, a callable giving that whole model, read from the file
    where not (the viewer holds the model, or reads it anyway: docs/viewer.md §2).  ``missing``: the relative size
    of the details the coarse stage lacks, ``sqrt(E_details / (E_approximation + E_details))`` with the details'
    field energy written with the file (their importance energy from its tiers in a file written before it) and
    the approximation's field energy (its B-splines overlap); ``outside``: that of the approximation's field off
    the content, which the full stage's content clamp removes, from the file's occupancy of the approximation (0
    for a file without it); in X-ray frames both from :meth:`lacks_in_line_integrals` instead
    (docs/raytracing.md §9).  Use from one thread at a time.  ``coarse``, where given: :func:`read_coarse`'s
    reading of the file (the viewer's, read before the rest), read here where not.
    """

    def __init__(self, tracer_class, path, device=None, device_memory=None, lod=False, whole=None, coarse=None):
        approximation, tiered, by_level, occupancy = read_coarse(path) if coarse is None else coarse
        self.levels = approximation.levels
        energies = [importance_of(g, None, approximation.frame).astype(np.float64) ** 2 for g in approximation.groups]
        read = sum(float(np.sum(e)) for e in energies)
        # the coarsest level's details and the finer levels' (a file written before that figure: the importance
        # energy, all of it counted as the coarsest level's)
        self._unread = (tiered, 0.0) if by_level is None else by_level
        unread = sum(self._unread)
        outside = 0.0  # the approximation's energy off its occupied blocks (a file without the occupancy: none)
        for e, g, occupied in zip(energies, approximation.groups, occupancy):
            if occupied is not None:
                share = mass_on_occupied(occupied, g.wavelet, self.levels).reshape(-1)[g.all_positions()]
                outside += float(np.sum(e * (1 - share)))
        # per group (§9): its wavelet, its channels and its importance energy over its coefficients' (channels
        # summed: importances take the largest channel), which scales its field's energies to the importances'
        self._parts, field = [], 0.0
        for e, g in zip(energies, approximation.groups):
            grid = approximation_grid(g)
            plain = float(np.sum(grid ** 2, dtype=np.float64)) * g.wavelet.norm_phi ** 6
            scale = float(np.sum(e)) / plain if plain > 0 else 0.0
            self._parts.append((g.wavelet, g.channels, scale))
            field += scale * field_energy(grid, g.wavelet.order)
        self._lattice = np.asarray(approximation.spacing) * 2 ** self.levels  # z, y, x
        self.missing = float(np.sqrt(unread / (field + unread))) if field + unread > 0 else 0.0
        self.outside = float(np.sqrt(outside / (read + tiered))) if read + tiered > 0 else 0.0  # importances both
        self._off = outside
        if len({g.wavelet.order for g in approximation.groups}) == 1:  # the same field on a lattice 2^levels coarser
            self.coarse = tracer_class(coarse_volume(approximation), device=device, device_memory=device_memory)
        else:  # the groups' lattices shift by half cells of the fine lattice: bricks of the coarsest detail
            self.coarse = tracer_class(approximation, device=device, device_memory=device_memory,
                                       lod=(approximation.levels,))
        # the ``detail=`` of the coarse stage's renders (None: its only one)
        self.coarse_detail = None if self.coarse.wv.levels == 0 else self.coarse.wv.levels
        self.full, self.full_seconds, self._failure, self._abandon = None, None, None, threading.Event()
        self._told = []  # the full stage's set-up's warnings not yet given (wait())
        # the stages share the device-memory budget: the full stage's bricks beyond what the coarse one leaves go
        # to its scratch file (docs/raytracing.md §6)
        left = self.coarse.budget.total - self.coarse.bricks.pool_bytes - 2 * self.coarse.block_bound.nbytes
        self._thread = threading.Thread(target=self._set_up, args=(tracer_class, path, max(left, 1), lod, whole),
                                        name="clwave-staged-setup", daemon=True)  # given up at exit: _abandon

    def _set_up(self, tracer_class, path, device_memory, lod, whole):
        start, cc = time.perf_counter(), self.coarse.cc
        try:
            with caught_warnings() as self._told:  # given again on the thread that takes the stage: wait()
                wv = WaveletVolume.open(path) if whole is None else whole()
                full = tracer_class(wv, device=cc, device_memory=device_memory, lod=lod, abandon=self._abandon)
        except Abandoned:
            return
        except BaseException as exc:  # raised again where the caller waits for the full stage
            self._failure = exc
            return
        self.full_seconds = time.perf_counter() - start
        self.full = full

    def start(self):
        """Start setting up the full stage (once): done by the first image of the coarse stage, so that the
        background's reading does not slow that image down, or by :meth:`wait`."""
        if self._thread.ident is None:
            atexit.register(_abandon, self._abandon, self._thread)
            self._thread.start()

    def abandon(self):
        """Give up the full stage's set-up (a viewer stopping): its thread stops after the file's reading or at the
        tracer's next checkpoint (between two slabs of the expansion, ``RayTracer``'s ``abandon``), as at the
        interpreter's exit (:func:`_abandon`), and the full stage is never ready (:meth:`wait` gives None once it
        has stopped)."""
        self._abandon.set()

    @property
    def ready(self) -> bool:
        """Whether the full stage's set-up has ended: the stage set up, its set-up failed (:attr:`failed`) or given
        up (:meth:`abandon`)."""
        return self._thread.ident is not None and not self._thread.is_alive()

    @property
    def failed(self) -> bool:
        """Whether the full stage's set-up failed: :meth:`render` goes on with the coarse stage, :meth:`wait` and
        :meth:`refine` raise its error."""
        return self.failure is not None

    @property
    def failure(self) -> BaseException | None:
        """The error the full stage's set-up failed with (:attr:`failed`), else None."""
        return self._failure if self.ready else None

    def wait(self, timeout=None):
        """The full stage's :class:`~clwave.RayTracer`, once set up (None if ``timeout`` seconds pass first, or once
        the set-up has been given up: :meth:`abandon`); the coarse stage is let go then (its memory)."""
        self.start()
        self._thread.join(timeout)
        if self._failure is not None:
            raise self._failure
        if self.full is not None:
            self.coarse = None
            told, self._told = self._told, []  # the set-up's warnings, once, to the caller (or a viewer's notes)
            for warning in told:
                warn_outside(warning)
        return self.full

    def render(self, camera: Camera | ConeBeam, **options):
        """One image from the best stage ready now: the full one (``options`` as :meth:`RayTracer.render`), or
        the coarse one at its coarsest detail (``detail=`` refused there), for good where the full stage's set-up
        failed or was given up.  ``meta["stage"]`` says which."""
        # the coarse stage taken before ``ready`` is read: a wait() from another thread (the viewer's) lets it go
        # once the full stage is ready, which this render then takes
        coarse = self.coarse
        full = self.wait(0) if self.ready and not self.failed else None
        if full is None and options.get("detail") is not None:
            raise InputError("detail= needs the full stage: wait() for it first")
        result = full.render(camera, **options) if full else coarse.render(camera, **options,
                                                                            detail=self.coarse_detail)
        result.meta["stage"] = "full" if full is not None else "coarse"
        self.start()
        return result

    def refine(self, camera: Camera | ConeBeam, tolerance=1e-3, lights=None, shading=True, absorption=True, *,
               error=None, transfer_function=None, clip=None):
        """Frames of ``camera`` from cheap to exact, for a viewer that shows each as it comes (a generator it stops
        iterating when the view changes; the set-up goes on).  While the full stage is not ready: the coarse stage
        on an image ``2^levels`` times smaller per side, then (if it is still not ready) on one twice as large;
        their estimates add what their size misses (the step from an image half as large) and what the details
        and the content clamp they lack change (:attr:`missing`, :attr:`outside`, docs/raytracing.md §9).  Then
        (waiting for it) the full stage's :meth:`RayTracer.refine`, full detail on reduced images and the last bit for
        bit its ``render``, from the image as large as the last coarse frame's (each frame at least the size and
        detail of the one before, docs/raytracing.md §8).  ``error=`` as :meth:`RayTracer.refine`;
        ``transfer_function``, ``clip``: as :meth:`RayTracer.render`'s, every stage classifying (clipping) with it.
        ``meta["stage"]`` says which stage made a frame.  The full stage's set-up failed: its error; given up
        (:meth:`abandon`): :class:`~clwave.threads.Abandoned`, where the full stage's frames would begin, as from a
        coarse frame's ``final_image()``."""
        check_error(error)
        check_camera(camera)
        options = dict(tolerance=tolerance, lights=lights, shading=shading, absorption=absorption,
                       transfer_function=as_transfer_function(transfer_function), clip=check_clip(clip))
        return self._frames(camera, options, error)

    def _frames(self, camera, options, error):
        view, start = camera.view((self.coarse or self.full).wv), time.perf_counter()
        final = FinalImage(lambda: self._full_stage().render(camera, **options).image)
        index, shown = 0, None  # shown: the last coarse frame
        for made in self._coarse_frames(camera, view, options, final, start):
            made.index, index, shown = index, index + 1, made
            yield made
            if reached(made, error):
                return
        full = self._full_stage()
        plan = schedule(view.size, full.details)  # after a coarse frame, images at least as large as its (§8)
        steps = None if shown is None else sum(reduction <= shown.reduction for _, reduction in plan)
        for made in frames(full, camera, options, steps=steps, error=error, final=final, previous=shown):  # §9
            made.index, made.seconds, made.meta["stage"] = index, time.perf_counter() - start, "full"
            index += 1
            yield made

    def _full_stage(self):
        """:meth:`wait` for the full stage, :class:`~clwave.threads.Abandoned` where it was given up."""
        full = self.wait()
        if full is None:
            raise Abandoned("the full stage was given up (StagedTracer.abandon): nothing to refine to")
        return full

    def lacks_in_line_integrals(self, image, view) -> float:
        """What the coarse stage's X-ray ``image`` (H, W, C) of ``view`` (its own, reduced view; along its central
        ray) lacks, relative to the line integrals of the whole field: each part's energy in the line integrals,
        the approximation's from that image, the details' and the clamped-off field's their energy times the share
        that white coefficients keep (the coarsest level's details', half of it for the finer levels', the
        approximation's B-splines'; :mod:`~clwave.raytrace.coarse_estimate`, docs/raytracing.md §9)."""
        direction = view.n[::-1] / self._lattice  # (z, y, x) lattice units
        seen = sum(scale * line_energy(image[..., list(channels)], view, self._lattice, self.levels)
                   for _, channels, scale in self._parts)
        coarsest, finer = self._unread  # level l < L keeps 2^(l - L) of level L's share: at most half (§9)
        unseen = (coarsest + finer / 2) * max(detail_share(w, direction) for w, _, _ in self._parts)
        off = self._off * max(white_share(w, direction, "aaa") for w, _, _ in self._parts)
        return float(np.sqrt((unseen + off) / (seen + unseen))) if seen + unseen > 0 else 0.0

    def _coarse_frames(self, camera, view, options, final, start):
        """The coarse stage's frames while the full stage is not ready (:meth:`refine`)."""
        # the coarse stage held here: a wait() from another thread (the viewer's) lets it go
        coarse, detail = self.coarse, self.coarse_detail
        if coarse is None or self.ready:
            return
        steps = ErrorEstimate()  # the coarse frames' size term: the step from the last image

        def render(reduction):
            cam = camera if reduction == 1 else camera.reduced(reduction, view)
            res = coarse.render(cam, detail=detail, **options)
            return upsample(res.image, view.size, reduction), res, cam

        smallest = 2 ** max(0, min(self.levels, int(np.log2(max(1, min(view.size) / MIN_SIDE)))))
        steps.add(render(2 * smallest)[0])  # the first frame's step: a pilot
        for reduction in sorted({smallest, max(smallest // 2, 1)}, reverse=True):
            if self.ready:
                return
            image, res, cam = render(reduction)
            rms, top = steps.add(image)
            peak = max(float(np.max(np.abs(image), initial=0.0)), np.finfo(np.float32).tiny)
            if options["absorption"]:  # the details or the clamp it lacks, the larger: kept details cancel the
                # approximation's haze off the content, which the clamp removes (§9); the max both, the clamp's with
                # a margin
                lacks = max(self.missing, self.outside)
                top += float(np.hypot(self.missing, CLAMP_MAX_MARGIN * self.outside))
            else:  # an X-ray frame's from its own image
                lacks = self.lacks_in_line_integrals(res.image, cam.view(coarse.wv))
                top += lacks
                if reduction == 1 and lacks > 0:  # the full image: its size misses nothing, and the term is its
                    rms = 0.0  # own line energies (§9); the max keeps the step, shaded frames both (measured)
            rms += lacks * root_mean_square(image) / peak
            self.start()
            yield RaytraceFrame(index=0, image=image, seconds=time.perf_counter() - start,
                                estimated_relative_rms_error=rms, estimated_relative_max_error=top,
                                meta=dict(res.meta, stage="coarse"), _final=final, detail=self.levels,
                                reduction=reduction)


def read_coarse(path) -> tuple:
    """What the coarse stage of a ``.clw`` file reads of it (:class:`StagedTracer`'s ``coarse=``, where a caller has
    read it already): its approximation (without the content mask: the coarse stage has no content clamp), the
    details' importance energy from the tiers (nothing more is read), their energy by level (the coarsest level's
    field energy written with the file and the finer levels' importance energy,
    :func:`~clwave.io.summary.detail_levels`; None for a file written before it), and the file's occupancy of the
    approximation."""
    approximation = WaveletVolume.open(path, approximation=True)
    approximation.content_mask = None
    tiered = detail_energy(path)
    return approximation, tiered, detail_levels(path, tiered), approximation_occupancy(path)


def _abandon(event, thread):
    """At exit: give up a full stage still being set up, and wait for its thread to stop, which it does after the
    file's reading or at the tracer's next checkpoint (``RayTracer``'s ``abandon``: between two slabs of the
    expansion).  A daemon
    thread stopped by the interpreter instead would keep h5py's lock, or abort inside OpenCL calls."""
    event.set()
    thread.join()


def coarse_volume(approximation: WaveletVolume) -> WaveletVolume:
    """The model of the approximation alone (levels L, one wavelet order) as a volume ``2^L`` times coarser per
    axis with no detail bands: the same field (docs/raytracing.md §8).  Level-L coefficient k spans fine cells
    ``o_L + 2^L k .. + 2^L j`` of a lattice of the volume's spacing; as a level-0 coefficient of a lattice of
    spacing ``2^L`` times that, normalised by ``2^(-3L/2)`` (docs/model.md §4), it spans cells ``k .. k + j`` of
    the coarse volume, whose origin puts them in the same place.  Bricks of the coarse volume cover ``2^L`` times
    more cells each than bricks of the coarsest detail, and segments are as long."""
    L, wv, wavelet = approximation.levels, approximation, approximation.groups[0].wavelet
    step, shape = 2 ** L, approximation.groups[0].bands[0].shape  # (z, y, x)
    spacing = np.array(wv.spacing[::-1]) * step  # (x, y, z), as the origin; fine = (world - origin) / s + (n - 1) / 2
    fine_corner = wavelet.offset("a", L) - (np.array(wv.shape[::-1]) - 1) / 2.0 - wavelet.order / 2.0
    coarse_corner = -(np.array(shape[::-1]) - 1) / 2.0 - wavelet.order / 2.0
    origin = np.array(wv.origin) + np.array(wv.spacing[::-1]) * fine_corner - spacing * coarse_corner
    half = np.array(wv.shape[::-1]) * np.array(wv.spacing[::-1]) / 2.0  # the framing of the volume itself
    content = wv.content if wv.content is not None else (tuple(wv.origin - half), tuple(wv.origin + half))
    bands = band_layout(wavelet, shape, 0)
    groups = [ChannelGroup(g.wavelet, g.channels, bands, g.positions, g.values * np.float32(step ** -1.5))
              for g in approximation.groups]
    return WaveletVolume(shape, spacing[::-1], origin, 0, groups, wv.channels, interpolate=wv.interpolate,
                         transfer_function=wv.transfer_function, content=content, subtracted=wv.subtracted,
                         obliquity=wv.obliquity, value_range=wv.value_range, photo=wv.photo)
