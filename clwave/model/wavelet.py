"""WaveletVolume: the sparse B-spline wavelet model both renderers stand on (docs/model.md).

Channels that share a wavelet form a :class:`ChannelGroup` with one index set; a group keeps its
kept coefficients as ascending global positions into its bands (coarsest approximation first)
and a (channels, K) float32 value table.  Importance order is derived on demand.
"""

from __future__ import annotations

import copy
from functools import cached_property, partial
from pathlib import Path

import numpy as np

from ..errors import InputError, file_name, flag, type_name
from ..io.progress import progress
from ..threads import MadeOnce, thread_map
from .bspline import SplineWavelet
from .budget import check_one_rule, check_thresholding, kept_count, warn_short_budget, warn_stored
from . import geometry
from .labels import warn_blurred_labels
from .mask import ContentMask
from .noise import band_noise, check_noise_known, measure_noise, signal_box, warn_kept_noise, warn_noise_gain
from .ranking import RankedTable, by_importance, ranked_table
from . import evaluation
from .transform import (apply_sampling_filter, check_decomposition, crop_to_grid, decompose, reconstruct_channel,
                        synthesize)
from .tf_file import stored_transfer_function
from .volume import Volume, warn_straight_colour


class ChannelGroup:
    """Channels sharing one wavelet, bands and index set."""

    def __init__(self, wavelet: SplineWavelet, channels, bands, positions, values):
        self.wavelet = wavelet
        self.channels = tuple(channels)
        self.bands = list(bands)
        self.positions = positions  # (K,) int64 ascending, or None for every position
        self.values = values        # (C, K) float32, channel-major for fast per-channel work

    @classmethod
    def gathered(cls, wavelet, channels, bands, parts, order=None) -> "ChannelGroup":
        """A group from ``parts`` ``[(positions, values (C, n)), ...]`` in any order (a chunked pass, a file's
        runs): positions made ascending, None when every position is there; ValueError for a position given
        twice.  ``order``: the stable argsort of the parts' positions, where the caller made it.  ``parts`` is
        emptied, so that each array the caller gave up is freed as soon as its sorted copy is made."""
        if len(parts) == 1:
            positions, values = parts.pop()
        else:
            positions = np.concatenate([p for p, _ in parts]) if parts else np.zeros(0, np.int64)
            values = (np.concatenate([v for _, v in parts], axis=1) if parts
                      else np.zeros((len(channels), 0), np.float32))
            parts.clear()
        if order is None:
            order = np.argsort(positions, kind="stable")  # timsort: parts made of ascending runs merge fast
        positions, gathered = np.take(positions, order), np.empty(values.shape, values.dtype)
        # per channel (several times faster than values[:, order]), in the host threads; "clip" (order is a
        # permutation) spares np.take a buffer for out=
        thread_map(lambda ch: np.take(values[ch], order, out=gathered[ch], mode="clip"), range(len(values)))
        values = order = None  # freed before the check below: the peak of opening a file (docs/chunked.md §4)
        if np.any(positions[1:] <= positions[:-1]):
            raise ValueError("a coefficient position is given twice")
        group = cls(wavelet, channels, bands, positions, gathered)
        if len(positions) == group.total:
            group.positions = None
        return group

    @property
    def total(self) -> int:
        return self.bands[-1].start + self.bands[-1].size

    @property
    def kept(self) -> int:
        return self.total if self.positions is None else len(self.positions)

    def band_slices(self) -> list:
        """Per band, the slice of the kept (ascending) positions that fall in it."""
        if self.positions is None:
            return [slice(b.start, b.start + b.size) for b in self.bands]
        edges = np.searchsorted(self.positions, [b.start for b in self.bands] + [self.total])
        return [slice(int(lo), int(hi)) for lo, hi in zip(edges[:-1], edges[1:])]

    def all_positions(self) -> np.ndarray:
        return np.arange(self.total, dtype=np.int64) if self.positions is None else self.positions

    def locate(self, positions):
        """Band number and (k_z, k_y, k_x) index of global positions (by arithmetic on each position: a pass over
        them all per band took most of :meth:`WaveletVolume.ranked`'s time)."""
        starts = np.array([b.start for b in self.bands], dtype=np.int64)
        shapes = np.array([b.shape for b in self.bands], dtype=np.int64)
        band_no = np.searchsorted(starts, positions, side="right") - 1
        index = np.empty((len(positions), 3), dtype=np.int64)
        rest = positions - starts[band_no]
        for axis in (2, 1):  # x, then y: the quotient left is the z index
            rest, index[:, axis] = np.divmod(rest, shapes[band_no, axis])
        index[:, 0] = rest
        return band_no, index

    def dense_bands(self) -> list:
        """Each band as a dense (nz, ny, nx, C) float64 array (zeros where not kept)."""
        flat = np.zeros((self.total, len(self.channels)), dtype=np.float64)
        flat[self.all_positions()] = self.values.T
        return [flat[b.start:b.start + b.size].reshape(*b.shape, -1) for b in self.bands]


class WaveletVolume:
    """Sparse B-spline wavelet coefficients of a volume and its continuous model.

    Build with :meth:`from_volume`, reduce with :meth:`threshold`, store with
    :meth:`save` / :meth:`open`.

    Examples
    --------
    >>> import clwave
    >>> vol = clwave.phantom("hydrogen", n=32)
    >>> wv = WaveletVolume.from_volume(vol, wavelet="cubic", levels=2).threshold(keep=0.05)
    >>> wv.kept, round(wv.compression, 3)
    (1638, 0.95)
    """

    #: what builds on this class and which it calls, set by those modules (imported with clwave): the model of a
    #: chunked volume (:mod:`clwave.model.chunked`), and the ``.clw`` file's ``(read, write)``
    #: (:mod:`clwave.io.clw`); this module imports neither (the model below its file format)
    chunked_model = None
    file_format = None

    def __init__(self, shape, spacing, origin, levels, groups, channels, *, interpolate=False,
                 focus=None, transfer_function=None, content=None, content_mask=None, subtracted=0.0, obliquity=0.0,
                 value_range=None, unit=None, photo=False, noise_sigma=None, provenance=None, modality=None):
        self.shape = tuple(int(s) for s in shape)
        self.spacing = tuple(float(s) for s in spacing)
        self.origin = tuple(float(o) for o in origin)
        self.subtracted = float(subtracted)  # the source volume's: its values are the input's minus it
        self.obliquity = float(obliquity)  # the source volume's Volume.obliquity: degrees off the scanner's axes
        # the source volume's (min, max) in the input's units (Volume.value_range), which post-classification clamps
        # the field to (docs/raytracing.md §10); None where not known (several channels, a .clw of before it)
        self.value_range = None if value_range is None else tuple(float(v) for v in value_range)
        self.unit = unit  # the source volume's Volume.unit: the world unit ("um", "mm"...), None where unknown
        self.photo = bool(photo)  # the source volume's Volume.photo: a photo's colour and alpha, not classified
        self.provenance = provenance  # the source volume's Volume.provenance: the file and frame read, or None
        self.modality = modality  # the source volume's Volume.modality: a DICOM series' Modality and units, or None
        # per channel the source volume's noise deviation where measured (measure_noise), else None
        self.noise_sigma = None if noise_sigma is None else tuple(None if s is None else float(s) for s in noise_sigma)
        self.levels = int(levels)
        self.groups = list(groups)
        self.channels = int(channels)
        self.interpolate = bool(interpolate)
        self.focus = focus  # ((x, y, z), sigma) used by threshold, or None
        self.transfer_function = transfer_function  # JSON-safe dict, or None
        # world (lo, hi) of the source volume's non-zero voxels: the default framing (Camera)
        self.content = None if content is None else tuple(tuple(float(c) for c in corner) for corner in content)
        # ContentMask: the source volume's non-zero voxels, beyond whose B-splines the approximating model of
        # every coefficient is zero (docs/raytracing.md §4); None where not known
        self.content_mask = content_mask
        self.source = None  # (path, keep) of the .clw file this model was opened from
        self._shared = MadeOnce()  # renderers of one-shot calls (shared)
        self._fine = {}  # group number -> (coefficients, start): the fine region evaluate made last (evaluation.py)

    # ------------------------------------------------------------------ build
    @classmethod
    def from_volume(cls, volume: Volume, wavelet="cubic", levels=None, *, interpolate=False,
                    transfer_function=None, scheduler=None, progress_bar=None):
        """Decompose every channel of ``volume`` (paper Fig. 1).

        Parameters
        ----------
        wavelet : str or sequence of str
            'haar', 'linear', 'quadratic' or 'cubic'; one per channel to mix orders
            (e.g. cubic RGB with Haar opacity, paper Fig. 14).
        levels : int, optional
            0 (the voxels' own B-splines) up to ``floor(log2(min axis)) - 1``.  Default: 3, or as many as
            the shortest axis allows, with a :class:`~clwave.ClwaveWarning` saying so (:func:`default_levels`).
        interpolate : bool
            False (default): the samples are the B-spline coefficients (paper eq. 8,
            approximating, mass preserving).  True: prefilter so the model passes
            through the samples (docs/model.md §1).
        transfer_function : TransferFunction, optional
            Stored with the volume (and in ``.clw`` files): for a classified volume, how it was classified;
            for a scalar one, the transfer function ray tracing classifies it with by default
            (post-classification, docs/raytracing.md §10).  Or a preset name, a ``.json``/``.csv`` file, a matplotlib
            colormap, a :meth:`TransferFunction.to_dict` (:func:`~clwave.model.tf_file.as_transfer_function`).
        scheduler : optional
            Chunked volumes only: the Dask scheduler of the passes (:mod:`clwave.schedulers`).

        Returns
        -------
        WaveletVolume, or for a chunked volume (:attr:`Volume.chunked`) a
        :class:`~clwave.model.chunked.ChunkedWaveletVolume` (docs/chunked.md), which never holds the
        coefficients: threshold it, then ``compute()`` or ``save()``.
        """
        if not isinstance(volume, Volume):
            volume = Volume(volume)
        interpolate = flag(interpolate, "interpolate")
        if scheduler is not None and not volume.chunked:
            raise InputError("scheduler= applies to a chunked volume (a Dask array, e.g. clwave.load of a Zarr or "
                             "HDF5 store, or chunks='auto'); this one is in memory",
                             cli="--workers and --scheduler apply to a chunked input (Zarr, HDF5, or --chunks auto)")
        warn_blurred_labels(volume, wavelet)
        warn_straight_colour(volume)
        if volume.chunked:
            return WaveletVolume.chunked_model.from_volume(volume, wavelet, levels, interpolate=interpolate,
                                                           transfer_function=transfer_function,
                                                           scheduler=scheduler, progress_bar=progress_bar)
        wavelets, levels = check_decomposition(volume.shape, volume.channels, wavelet, levels)
        tf = stored_transfer_function(transfer_function)
        mask = volume.content_mask()
        groups = []
        for wav in dict.fromkeys(wavelets):
            chans = [c for c, w in enumerate(wavelets) if w == wav]
            bands, values = decompose(volume, wav, chans, levels, interpolate, progress_bar)
            groups.append(ChannelGroup(wav, chans, bands, None, values))
        return cls(volume.shape, volume.spacing, volume.origin, levels, groups, volume.channels, photo=volume.photo,
                   interpolate=interpolate, transfer_function=tf, content=volume.content_box(mask), unit=volume.unit,
                   content_mask=None if interpolate else ContentMask.of(mask), subtracted=volume.subtracted,
                   obliquity=volume.obliquity, value_range=volume.value_range(), provenance=volume.provenance,
                   modality=volume.modality)

    # ------------------------------------------------------------- properties
    @property
    def wavelets(self) -> tuple:
        """Wavelet name of each channel."""
        names = {c: g.wavelet.name for g in self.groups for c in g.channels}
        return tuple(names.get(c) for c in range(self.channels))

    @property
    def n_voxels(self) -> int:
        return int(np.prod(self.shape))

    @property
    def kept(self) -> int:
        """Coefficient positions kept (per group; the largest group count)."""
        return max(g.kept for g in self.groups)

    @property
    def compression(self) -> float:
        """Fraction discarded, ``1 - kept / number_of_voxels`` (as the paper reports it).

        An unthresholded transform has a few more positions than voxels (the zero
        extension, docs/model.md §3), so its compression is slightly negative.
        """
        return 1.0 - float(np.mean([g.kept for g in self.groups])) / self.n_voxels

    @property
    def classified(self) -> bool:
        """Whether this is a classified model ``(q_R, q_G, q_B, alpha)``, which ray tracing shades as it is: 4 channels,
        not a photo's colour and alpha (:attr:`Volume.photo`, docs/model.md §5)."""
        return self.channels == 4 and not self.photo

    def __repr__(self):
        return (f"WaveletVolume(shape={self.shape}, wavelets={self.wavelets}, levels={self.levels}, "
                f"kept={self.kept}, compression={self.compression:.4f})")

    def measure_noise(self):
        """Per channel, the noise deviation of the source volume's voxels (in the stored values' units), estimated
        from the finest diagonal band (:mod:`clwave.model.noise`, docs/model.md §2) and recorded as
        :attr:`noise_sigma`, which the models :meth:`threshold` makes and ``.clw`` files keep; None for a channel
        whose band does not look like noise (a clean volume); None where it cannot be measured (0 levels, a thresholded
        model that records none)."""
        if self.noise_sigma is None:
            self.noise_sigma = measure_noise(self)
        return self.noise_sigma

    @cached_property
    def signal_box(self):
        """World (x, y, z) ``(lo, hi)`` of a noisy model's content above its noise (:func:`.noise.signal_box`), or None:
        found once per model (it is immutable; its noise measured then, if it can be), as every view frames it."""
        return signal_box(self)

    def content_box(self):
        """World (x, y, z) corners ``(lo, hi)`` of the non-zero voxels of the volume the model was made
        from (:meth:`Volume.content_box`), or None where that is not known."""
        return None if self.content is None else (np.array(self.content[0]), np.array(self.content[1]))

    # ----------------------------------------------------------- importance
    @property
    def frame(self) -> tuple:
        """``(shape, spacing, origin)``: where the fine lattice sits in the world (geometry.fine_to_world)."""
        return self.shape, self.spacing, self.origin

    def importance(self, group: ChannelGroup) -> np.ndarray:
        """:func:`band_importance` of each kept position of the group (with this model's focus)."""
        return importance_of(group, self.focus, self.frame)

    # ------------------------------------------------------------- threshold
    def threshold(self, keep=None, threshold=None, focus=None, noise=None) -> "WaveletVolume":
        """Keep the most important coefficient positions (docs/model.md §2).

        Parameters
        ----------
        keep : float in (0, 1]
            Keep ``round(keep * number_of_voxels)`` positions (1: every coefficient): the coarsest
            approximation band first (its largest coefficients if the budget is
            smaller), then details by ``|c| * ||basis||`` (max over channels).
        threshold : float >= 0
            Keep the approximation band and every detail whose importance exceeds it.
        focus : ((x, y, z), sigma), optional
            Local level of detail (paper Fig. 12/13): importance is weighted by
            ``exp(-d^2 / 2 sigma^2)``, d the world distance from the focus to the
            centre of the basis support, so detail survives near the focus.
        noise : float >= 0
            Keep the approximation band and every detail above ``noise`` times the noise level of its band: the
            voxels' noise deviation, estimated from the finest band (:meth:`measure_noise`), times the band's
            analysis norm (wavelet shrinkage, docs/model.md §2); e.g. 3 on a noisy volume.
        """
        check_one_rule(keep, threshold, noise)
        keep, threshold, focus, noise = check_thresholding(keep, threshold, focus, noise)
        if noise is not None:
            if self.interpolate:
                raise InputError("noise= needs the approximating model (interpolate=False): the interpolating "
                                 "prefilter colours the noise, whose level in each band assumes it white",
                                 cli="--noise cannot go with --interpolate: the prefilter colours the noise")
            check_noise_known(self.measure_noise(), self.levels)
            warn_noise_gain([(g.wavelet, g.bands) for g in self.groups], self.levels)
        out = WaveletVolume(self.shape, self.spacing, self.origin, self.levels, [], self.channels,
                            interpolate=self.interpolate, focus=focus, transfer_function=self.transfer_function,
                            content=self.content, content_mask=self.content_mask, subtracted=self.subtracted,
                            obliquity=self.obliquity, value_range=self.value_range, unit=self.unit, photo=self.photo,
                            provenance=self.provenance, modality=self.modality,
                            noise_sigma=self.noise_sigma)  # where measured: a chunked model's file records the same
        budget = None if keep is None else kept_count(keep, self.n_voxels)
        threshold = threshold if noise is None else noise
        short = 0  # the most approximation coefficients of a group the budget cannot hold
        for g in self.groups:
            # one float32 per position, no index array of them all (the peak of compressing, docs/benchmarks.md §2)
            imp = importance_of(g, focus, self.frame,
                                None if noise is None else band_noise([self.noise_sigma[c] for c in g.channels]))
            zero = g.values[0] == 0
            for row in g.values[1:]:
                zero &= row == 0
            imp[zero] = -1  # a zero coefficient is never kept: below every importance (>= 0)
            zero = None
            stop = g.band_slices()[0].stop  # the approximation band ranks first
            approx, detail = np.flatnonzero(imp[:stop] >= 0), imp[stop:]
            if budget is None:  # a threshold, or keep=1: every live coefficient (importance >= 0)
                # compared in float64: a threshold past float32 (1e308) cast to it was NumPy's overflow warning
                chosen = np.concatenate([approx, stop + np.flatnonzero(detail > np.float64(threshold) if keep is None
                                                                       else detail >= 0)])
            elif budget <= len(approx):
                chosen = approx[_top(imp[approx], budget)]
                short = max(short, len(approx) if budget < len(approx) else 0)
            else:
                live, count = detail >= 0, budget - len(approx)  # below the live count, _top never reaches a -1
                top = np.flatnonzero(live) if count >= np.count_nonzero(live) else _top(detail, count)
                live = None
                chosen = np.concatenate([approx, stop + top])
            imp = detail = None
            out.groups.append(ChannelGroup(g.wavelet, g.channels, g.bands,
                                           chosen if g.positions is None else g.positions[chosen],
                                           np.ascontiguousarray(g.values[:, chosen])))
        if short:  # the approximation band ranks first: no detail, and part of it dropped
            warn_short_budget(keep, budget, short, self.n_voxels)
        warn_kept_noise(self, out, keep, threshold, importance_of)
        return out

    # ------------------------------------------------------- upload views
    def ranked(self, group: int = 0) -> RankedTable:
        """The group's coefficients by decreasing importance across all bands, ties by position, with their
        importance: the order splatting draws them in and progressive refinement adds them, in the table the splat
        renderer holds."""
        return self._ranked[group]

    @cached_property
    def _ranked(self) -> list:
        tables = []
        for g in self.groups:
            imp = self.importance(g)
            tables.append(ranked_table(g, by_importance(imp), importance=imp))
        return tables

    def bands(self, group: int = 0):
        """Per level and subband: ``(Band, index (K, 3) int32, values (K, C))``, by importance."""
        table, g = self.ranked(group), self.groups[group]
        out = []
        for band in g.bands:
            sel = table.band == band.id
            out.append((band, table.index[sel], table.values[sel]))
        return out

    # -------------------------------------------------------- evaluation
    def evaluate(self, points, method: str = "auto") -> np.ndarray:
        """The continuous model at world points (N, 3) as (x, y, z); returns (N, C) float64, in the stored values: the
        input's minus :attr:`subtracted` (a 40 HU voxel of a CT loaded with ``subtract=-1000`` is 1040 here,
        model.md §5).

        The model of every kept coefficient, the content mask's clamp not applied (the ray tracer's field is zero
        on empty voxels, docs/raytracing.md §4; :meth:`unmasked` evaluates alike).  ``method``: ``"bands"`` sums
        every band's basis functions at each point (nothing made beforehand; the ray tracer's float64 oracle);
        ``"fine"`` synthesises the fine B-spline coefficients of the region the points read and reads those
        (docs/model.md §4); ``"auto"`` (default) takes the fine path where the points repay the region's synthesis.
        The fine coefficients last made are kept for the next call, at most 128 MiB a channel group with ``"auto"``
        (float64, :data:`~clwave.model.evaluation.REGION_BYTES`; a larger region goes in slabs, and a slab still
        larger takes the band sum; ``"fine"`` makes every slab, 16 z layers of the region at most);
        :meth:`release` frees them.
        """
        return evaluation.evaluate(self, points, False, method)

    def gradient(self, points, method: str = "auto") -> np.ndarray:
        """Analytic gradient (paper eq. 14-16, docs/model.md §4) at world points: (N, C, 3) as d/dx, d/dy, d/dz, of the
        stored values (the value subtracted, a constant, moves no gradient); ``method`` and the memory kept as
        :meth:`evaluate`'s."""
        return evaluation.evaluate(self, points, True, method)

    # ------------------------------------------------------ reconstruction
    def fine_coefficients(self, group: int = 0):
        """Real-line synthesis down to level 0: the fine-level B-spline coefficients.

        Returns ``(coeffs, start)``: ``coeffs`` (Z, Y, X, C) float64 with
        ``coeffs[i, j, k]`` the coefficient of ``N_j(x - (start + (i, j, k)))``.
        ``start`` can be negative: after thresholding the model reaches beyond
        the voxel grid, and nothing is cropped here.
        """
        g = self.groups[group]
        return synthesize(g.wavelet, g.bands, partial(evaluation.group_box, g))

    def reconstruct(self) -> Volume:
        """The voxel data the model represents, as a float32 :class:`Volume`.

        For the approximating model these are the fine B-spline coefficients on the
        voxel grid (``pywt.waverecn``, which equals the real-line synthesis there);
        with ``interpolate=True`` the model's values at the voxel centres.
        """
        data = np.zeros(self.shape + (self.channels,), dtype=np.float32)
        for gi, g in enumerate(self.groups):
            if self.interpolate:  # needs the coefficients just beyond the grid too
                coeffs, start = apply_sampling_filter(*self.fine_coefficients(gi), g.wavelet)
                data[..., list(g.channels)] = crop_to_grid(coeffs, start, self.shape)
                continue
            dense = g.dense_bands()
            for slot, channel in enumerate(g.channels):
                data[..., channel] = reconstruct_channel(g, dense, slot, self.shape, self.levels)
        return Volume(data if self.channels > 1 else data[..., 0], self.spacing, self.origin, self.subtracted,
                      self.obliquity, unit=self.unit, photo=self.photo, provenance=self.provenance,
                      modality=self.modality)

    def unmasked(self) -> "WaveletVolume":
        """The same coefficients without the content mask (nothing clamped, docs/raytracing.md §4), keeping no
        renderer of this model's (they may depend on the mask)."""
        out = copy.copy(self)
        out.content_mask, out._shared = None, MadeOnce()
        return out

    # ----------------------------------------------------------- renderers
    def shared(self, key, make):
        """The object ``make()`` builds for ``key``, made once and kept with this model, so that one-shot
        calls (``clwave.splat``, ``raytrace``, ``progressive``) on the same model and device reuse what a
        renderer uploads and builds; released with the model (or by :meth:`release`).  Threads that ask for one key
        at once get one object: the others wait for the first's ``make()`` (two tracers built at once, sharing the
        device's kernels, gave wrong bricks until thread22)."""
        return self._shared.get(key, make)

    def release(self):
        """Drop the renderers one-shot calls have kept (their device memory goes with them) and the fine
        coefficients :meth:`evaluate` kept."""
        self._shared.clear()
        self._fine.clear()

    def __getstate__(self):
        """Pickled (for a Dask worker process, ``copy.deepcopy``) without what :meth:`release` drops: renderers
        hold this process's OpenCL objects, which do not pickle; the copy makes its own when it renders."""
        return dict(self.__dict__, _shared=MadeOnce(), _fine={})

    def __copy__(self):
        """A shallow copy shares everything, kept renderers and regions included (:meth:`unmasked` keeps the fine
        regions, which ignore the mask), as it did before :meth:`__getstate__`, which ``copy.copy`` would use."""
        out = object.__new__(type(self))
        out.__dict__.update(self.__dict__)
        return out

    # ------------------------------------------------------------- files
    def save(self, path, overwrite=False, quantise=None) -> Path:
        """Write a ``.clw`` file (docs/model.md §6, :mod:`clwave.io.clw`); refuses to replace an
        existing file unless ``overwrite``; writes atomically.  ``quantise``: a bound on the change of any
        voxel of :meth:`reconstruct`, or "auto", stores the values rounded to a step (docs/codecs.md)."""
        return WaveletVolume.file_format[1](self, path, overwrite, quantise)

    @classmethod
    def open(cls, path, keep=None, *, approximation=False) -> "WaveletVolume":
        """Read a ``.clw`` file written by :meth:`save`; with ``keep``, only its most important coefficients,
        reading about that fraction of the file: the same model as ``open(path).threshold(keep=keep)``
        (docs/chunked.md §4); with ``approximation``, the coarsest approximation alone (a first image at once,
        docs/raytracing.md §8).  The content mask is read when first used, a part at a time."""
        wv = WaveletVolume.file_format[0](file_name(path), keep, approximation)
        if not approximation:
            wv.source = (str(Path(path).resolve()), keep)  # workers of a Dask cluster open it themselves
            warn_stored(wv, keep, path)
        return wv


# ---------------------------------------------------------------- helpers


#: the share of coefficients kept where nothing says (clwave compress, view): a model for a first look
DEFAULT_KEEP = 0.05


def importance_of(group: ChannelGroup, focus, frame, noise=None) -> np.ndarray:
    """:func:`band_importance` of each kept position of ``group``, in position order (a bar counts its coefficients,
    a band at a time: the finest level's hold about 7/8 of them)."""
    imp, positions = np.empty(group.kept, dtype=np.float32), group.all_positions()
    with progress(total=group.kept, desc="importance") as bar:
        for band, sl in zip(group.bands, group.band_slices()):
            index = None if focus is None else np.column_stack(np.unravel_index(positions[sl] - band.start, band.shape))
            imp[sl] = band_importance(group.wavelet, band, group.values[:, sl], index, focus, frame, noise)
            bar.update(sl.stop - sl.start)
    return imp


def band_importance(wavelet, band, values, index, focus, frame, noise=None) -> np.ndarray:
    """Importance of coefficients of one band: ``|c| * ||basis||`` (max over channels), float32, times the
    focus weight ``exp(-d^2 / 2 sigma^2)`` (d: world distance from the focus to the centre of the basis
    support) when ``focus`` is given; ``values`` (C, n), ``index`` (n, 3) their (k_z, k_y, k_x) (used only
    with focus), ``frame`` :attr:`WaveletVolume.frame`.  With ``noise`` (the voxels' noise deviation per channel,
    :mod:`~clwave.model.noise`), ``|c|`` in units of the noise of its band instead, ``|c| / (noise * ||analysis||)``
    (``inf`` where a channel measured no noise).  The one definition thresholding, ``.clw`` tiers and chunked passes
    share (docs/model.md §2)."""
    if values.shape[1] == 0:
        return np.zeros(0, dtype=np.float32)
    if noise is None:
        imp = np.abs(values).max(axis=0)
        imp *= np.prod([wavelet.norm(letter) for letter in band.key])
    else:
        level = np.prod([wavelet.analysis_norm(letter, band.level) for letter in band.key]) * np.asarray(noise)
        with np.errstate(divide="ignore", invalid="ignore"):  # no noise: a live coefficient is inf, a zero nan
            imp = np.nan_to_num(np.abs(values) / level[:, None], nan=0.0, posinf=np.inf).max(axis=0).astype(np.float32)
    if focus is not None:
        centre, sigma = focus
        fine = geometry.support_centres(wavelet, band.key, band.level, index)
        world = geometry.fine_to_world(fine, wavelet.order, *frame)
        with np.errstate(over="ignore"):  # d / sigma beyond float range: a weight of 0 (any finite sigma > 0)
            imp *= np.exp(-0.5 * np.sum(((world - np.asarray(centre)) / sigma) ** 2, axis=1))
    return imp


def _top(importance, count) -> np.ndarray:
    """Indices of the ``count`` largest values (exact count), ascending; of the values tied at the cut, the
    lowest indices.  Every caller passes importances in position order, so ties go to the lowest positions
    whatever order the coefficients were computed in (docs/chunked.md §3)."""
    if count >= len(importance):
        return np.arange(len(importance))
    if count <= 0:
        return np.zeros(0, dtype=np.int64)
    cut = np.partition(importance, len(importance) - count)[len(importance) - count]  # the count-th largest
    above = importance > cut
    tied = np.flatnonzero(importance == cut)[:count - int(np.count_nonzero(above))]
    above[tied] = True
    return np.flatnonzero(above)


def check_model(wv, work: str):
    """An InputError naming ``work`` ("splatting") where ``wv`` is no :class:`WaveletVolume`: a chunked model (of a
    Dask array) is written to a file and opened first (docs/chunked.md); for an array or a Volume the line names the
    calls that make a model of it and :func:`clwave.view`, which looks at it in one."""
    if not isinstance(wv, WaveletVolume):
        chunked = WaveletVolume.chunked_model is not None and isinstance(wv, WaveletVolume.chunked_model)
        given = "volume" if isinstance(wv, Volume) else "data"
        volume = given if isinstance(wv, Volume) else f"clwave.Volume({given})"
        fix = ("save it (.save('x.clw')) and render WaveletVolume.open('x.clw')" if chunked else
               f"make one, clwave.WaveletVolume.from_volume({volume}).threshold(keep={DEFAULT_KEEP}), and render it "
               f"(or look at it in one call: clwave.view({given}))")
        raise InputError(f"{work} needs a clwave.WaveletVolume (a model), got {type_name(wv)}: {fix}")
