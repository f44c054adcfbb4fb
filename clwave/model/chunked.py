"""The wavelet model of a chunked volume, computed chunk by chunk on Dask (docs/chunked.md §2-4).

A :class:`ChunkedWaveletVolume` holds no coefficients.  It holds, per channel group, the transform as
a Dask graph (:func:`level_stacks`: level by level, each block of a level's input with the halo its
filters need, transformed by PyWavelets exactly as the in-memory transform does) and a selection rule
per class of coefficients (the coarsest approximation, the details: :class:`Rule`).  Each pass runs
the graph and streams small per-block results back (:func:`clwave.schedulers.stream`): importance
histograms, from which ``keep=`` finds its exact cut, or the selected coefficients, gathered into a
:class:`WaveletVolume` (:meth:`compute`) or written to a ``.clw`` file as they come (:meth:`save`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from itertools import product
from pathlib import Path

import numpy as np
import pywt

from ..schedulers import client_for, stream
from ..errors import InputError
from .bspline import SplineWavelet
from .transform import KEYS, band_layout, check_coefficients
from .tf_file import stored_transfer_function
from .volume import Volume, content_of
from .mask import ContentMask
from .budget import check_one_rule, check_thresholding, kept_count, warn_short_budget
from . import noise
from .noise import check_noise_known, warn_noise_gain
from .wavelet import ChannelGroup, WaveletVolume, _top, band_importance, check_decomposition

MIN_BLOCK_VOXELS = 1 << 21  # smaller chunks are merged into blocks of at least this many voxels (task overhead)
MAX_BLOCKS = 4096           # and into at most this many blocks a level
BIN_SHIFT = 16           # histogram bins: the top 16 bits of a float32 importance (monotone for x >= 0)
TIER_SHIFT = 20          # .clw tiers: the top 12 bits (eight tiers an octave, docs/chunked.md §4)
APPROX, DETAIL = 0, 1    # the two classes of coefficients, ranked in this order


def importance_keys(importance: np.ndarray) -> np.ndarray:
    """The bits of float32 importances >= 0 as uint32: the same order as the values."""
    return np.ascontiguousarray(importance, dtype=np.float32).view(np.uint32)


def tiers_of(importance: np.ndarray) -> np.ndarray:
    """The ``.clw`` tier of each importance (eight a binary octave; higher is more important)."""
    return (importance_keys(importance) >> TIER_SHIFT).astype(np.int16)


def tier_energy(tiers) -> np.ndarray:
    """float64: the squared importance each tier (>= 0, finite) stands for, its geometric middle squared: the product
    of its bounds, within ``9/8`` of each of its importances squared (a tier is 3 mantissa bits, linear within an
    octave: the bounds of an octave's k-th tier are ``(9 + k) / (8 + k)`` apart, at most 9/8)."""
    tiers = np.asarray(tiers).astype(np.uint32)
    return ((tiers << TIER_SHIFT).view(np.float32).astype(np.float64)
            * ((tiers + 1) << TIER_SHIFT).view(np.float32))


@dataclass(frozen=True)
class Rule:
    """Which coefficients of one class a pass keeps: ``every`` position (zeros too: the unthresholded
    model), the live ones (non-zero in some channel) whose importance exceeds ``above``, or, when
    ``bin`` is set, the live ones in histogram bins above ``bin`` and the ``take`` most important of
    bin ``bin`` itself (the exact cut of a budget)."""

    every: bool = False
    above: float | None = None   # None: no importance bound
    bin: int | None = None
    take: int = 0
    none: bool = False

    def kept(self, imp):
        """(kept mask, candidate mask) over live coefficients of importance ``imp``."""
        if self.none:
            return np.zeros(len(imp), bool), np.zeros(len(imp), bool)
        if self.bin is not None:
            bins = importance_keys(imp) >> BIN_SHIFT
            return bins > self.bin, bins == self.bin
        if self.above is not None:
            return imp > self.above, np.zeros(len(imp), bool)
        return np.ones(len(imp), bool), np.zeros(len(imp), bool)


@dataclass(frozen=True)
class Plan:
    """What a block task needs to know (small, pickled to workers)."""

    order: int
    bands: tuple
    levels: int
    frame: tuple
    focus: tuple | None
    rules: tuple = (Rule(), Rule())
    noise: tuple | None = None  # per channel of the group: importances in units of each band's noise (noise=)

    @property
    def wavelet(self) -> SplineWavelet:
        return SplineWavelet(self.order)

    def band(self, level, key):
        if level == self.levels and key == "aaa":
            return self.bands[0]
        m_index = self.levels - level  # details of level m follow the approximation, coarsest first
        return self.bands[1 + 7 * m_index + KEYS.index(key) - 1]


class ChunkedWaveletVolume:
    """The wavelet model of a chunked :class:`Volume`, never held whole (docs/chunked.md).

    Made by :meth:`WaveletVolume.from_volume` for a chunked volume.  :meth:`threshold` selects exactly
    the coefficients the in-memory model would (ties too: to the lowest positions); :meth:`compute` gathers
    the selection into a :class:`WaveletVolume`; :meth:`save` streams it into a ``.clw`` file.  Every pass runs on
    ``scheduler`` (:mod:`clwave.schedulers`).
    """

    def __init__(self, volume: Volume, wavelets, levels, *, transfer_function=None, focus=None,
                 rules=None, content=None, scheduler=None, progress_bar=None, value_range=None, noise_sigma=None,
                 by_noise=False):
        self.volume = volume
        self._wavelets = tuple(wavelets)
        self.levels = int(levels)
        self.transfer_function = transfer_function
        self.focus = focus
        # per channel group, the (approximation, detail) rules; by default every position (no threshold)
        self.rules = tuple(rules or [(Rule(every=True), Rule(every=True))] * len(self.groups()))
        self.content = content
        self.value_range = value_range  # the volume's (min, max), input units (Volume.value_range)
        self.scheduler = scheduler
        self.progress_bar = progress_bar
        self.kept = None  # coefficient positions kept (the largest group's count), known after a selection pass
        self.noise_sigma = noise_sigma  # per channel, as WaveletVolume.noise_sigma; measured by threshold(noise=)
        self.by_noise = by_noise  # the details are kept by their importance in units of their band's noise

    @classmethod
    def from_volume(cls, volume: Volume, wavelet="cubic", levels=None, *, interpolate=False, transfer_function=None,
                    scheduler=None, progress_bar=None) -> "ChunkedWaveletVolume":
        """The model of a chunked volume; reads it once here, for its content (the default framing) and its range
        (post-classification's clamp)."""
        if interpolate:
            raise InputError("interpolate=True needs the whole volume at once (its prefilter is global); a "
                             "chunked volume takes the approximating model (interpolate=False)",
                             cli="--interpolate needs the whole volume in memory; leave it out for a chunked input")
        wavelets, levels = check_decomposition(volume.shape, volume.channels, wavelet, levels)
        tf = stored_transfer_function(transfer_function)
        with client_for(scheduler) as client:
            content, value_range = volume.content_box_and_value_range(client, progress_bar)
        return cls(volume, wavelets, levels, transfer_function=tf, scheduler=scheduler, progress_bar=progress_bar,
                   value_range=value_range,
                   content=None if content is None else tuple(tuple(float(c) for c in corner) for corner in content))

    # ------------------------------------------------------------- properties
    shape = property(lambda self: self.volume.shape)
    spacing = property(lambda self: self.volume.spacing)
    origin = property(lambda self: self.volume.origin)
    subtracted = property(lambda self: self.volume.subtracted)
    obliquity = property(lambda self: self.volume.obliquity)
    unit = property(lambda self: self.volume.unit)
    photo = property(lambda self: self.volume.photo)
    provenance = property(lambda self: self.volume.provenance)
    modality = property(lambda self: self.volume.modality)
    channels = property(lambda self: self.volume.channels)
    n_voxels = property(lambda self: int(np.prod(self.shape)))
    frame = property(lambda self: (self.shape, self.spacing, self.origin))

    @property
    def wavelets(self) -> tuple:
        return tuple(w.name for w in self._wavelets)

    def groups(self) -> list:
        """``(wavelet, channels)`` per channel group, in the in-memory model's order."""
        return [(w, [c for c, x in enumerate(self._wavelets) if x == w]) for w in dict.fromkeys(self._wavelets)]

    def __repr__(self):
        return (f"ChunkedWaveletVolume(shape={self.shape}, wavelets={self.wavelets}, levels={self.levels}, "
                f"chunks={self.volume.data.chunksize})")

    content_box = WaveletVolume.content_box

    # ------------------------------------------------------------- passes
    def _plan(self, wavelet, gi, focus=None):
        sigmas = tuple(noise.band_noise([self.noise_sigma[c] for c in self.groups()[gi][1]])) if self.by_noise else None
        return Plan(wavelet.order, tuple(band_layout(wavelet, self.shape, self.levels)), self.levels, self.frame,
                    focus, self.rules[gi], sigmas)

    def _tasks(self, fn, wavelet, channels, plan, finest=False):
        """One delayed ``fn(subbands, level, band offsets, plan)`` per block of every level (of level 1 alone with
        ``finest``)."""
        import dask

        source = self.volume.data if self.volume.data.ndim == 4 else self.volume.data[..., None]
        tasks = []
        for level, stack, starts in level_stacks(source[..., channels], wavelet, self.levels, plan.bands,
                                                 plan.frame[:2]):
            for index, block in np.ndenumerate(stack.to_delayed()[0, ..., 0]):
                offsets = tuple(int(s[i]) for s, i in zip(starts, index))
                tasks.append(dask.delayed(fn)(block, level, offsets, plan))
            if finest:
                break
        return tasks

    def threshold(self, keep=None, threshold=None, focus=None, noise=None) -> "ChunkedWaveletVolume":
        """Select the coefficients :meth:`WaveletVolume.threshold` keeps (the same arguments), without
        holding them: ``threshold=`` is a rule; ``keep=`` runs one pass of importance histograms here to
        find its exact cut (docs/chunked.md §3); ``noise=`` two passes over the finest level here to measure the
        noise (:meth:`measure_noise`).  Returns a new chunked model; nothing is gathered."""
        check_one_rule(keep, threshold, noise)
        keep, threshold, focus, noise = check_thresholding(keep, threshold, focus, noise)
        if not all(_keeps_every(rules) for rules in self.rules):
            raise InputError("this chunked model is thresholded already: threshold the model from_volume gave, or "
                             "compute() this one and threshold that")
        sigma = self.noise_sigma
        if noise is not None:
            if self.levels == 0:  # refused before the passes
                check_noise_known(None, 0)
            sigma = self.measure_noise()
            check_noise_known(sigma, self.levels)  # then the gain told, as the in-memory model tells it
            warn_noise_gain([(w, band_layout(w, self.shape, self.levels)) for w, _ in self.groups()], self.levels)
        budget = None if keep is None else kept_count(keep, self.n_voxels)
        if budget is None:  # a threshold, or keep=1: every live coefficient
            rules = [(Rule(), Rule(above=threshold if noise is None else noise))] * len(self.groups())
        else:
            hists = self._histograms(focus)
            short = max((n for n in (int(h[APPROX].sum()) for h in hists) if budget < n), default=0)
            if short:  # told before the selection pass, as the in-memory model tells it
                warn_short_budget(keep, budget, short, self.n_voxels)
            rules = [_cut(hist, budget) for hist in hists]
        return ChunkedWaveletVolume(self.volume, self._wavelets, self.levels, transfer_function=self.transfer_function,
                                    focus=focus, rules=rules, content=self.content, scheduler=self.scheduler,
                                    progress_bar=self.progress_bar, value_range=self.value_range, noise_sigma=sigma,
                                    by_noise=noise is not None)

    def measure_noise(self) -> tuple:
        """Per channel, the voxels' noise deviation as :attr:`WaveletVolume.noise_sigma` gives it, bit for bit
        (:mod:`~clwave.model.noise`): from a histogram of the finest diagonal band's non-zero interior |d|, then the
        values of the bin that holds their lower median, in two passes over the first level; recorded in the models
        :meth:`threshold` makes (and their files), as the in-memory model records it once measured."""
        if self.noise_sigma is not None:
            return self.noise_sigma
        sigmas = [None] * self.channels
        with client_for(self.scheduler) as client:
            for gi, (wavelet, channels) in enumerate(self.groups()):
                plan = self._plan(wavelet, gi)
                hist = np.zeros((len(channels), 1 << (32 - noise.BIN_SHIFT)), dtype=np.int64)
                tasks = self._tasks(_finest_block, wavelet, channels, plan, finest=True)
                for per_channel in stream(client, tasks, desc="noise histogram", progress_bar=self.progress_bar):
                    hist += per_channel
                medians = [noise.median_rank(h) for h in hist]
                within = [[] for _ in channels]
                bins = [b for _, b, _ in medians]
                tasks = self._tasks(partial(_finest_block, bins=bins), wavelet, channels, plan, finest=True)
                for per_channel in stream(client, tasks, desc="noise median", progress_bar=self.progress_bar):
                    for c, values in enumerate(per_channel):
                        within[c].append(values)
                for c, (channel, (rank, _, below)) in enumerate(zip(channels, medians)):
                    values = np.concatenate(within[c])
                    median = float(np.partition(values, rank - below)[rank - below]) if len(values) else 0.0
                    sigmas[channel] = noise.sigma_of(hist[c], median, wavelet)
        self.noise_sigma = tuple(sigmas)
        return self.noise_sigma

    def _histograms(self, focus):
        """Per group, the importance histograms (2, 2^16) of its live approximation and detail coefficients."""
        out = []
        with client_for(self.scheduler) as client:
            for gi, (wavelet, channels) in enumerate(self.groups()):
                hist = np.zeros((2, 1 << (32 - BIN_SHIFT)), dtype=np.int64)
                tasks = self._tasks(_histogram_block, wavelet, channels, self._plan(wavelet, 0, focus))
                for per_class in stream(client, tasks, desc=f"{wavelet.name} histograms",
                                        progress_bar=self.progress_bar):
                    for c, (bins, counts) in enumerate(per_class):
                        np.add.at(hist[c], bins, counts)
                out.append(hist)
        return out

    def selected(self, client, *, tiers=False):
        """Yield ``(group, positions, values (C, n)[, tiers])`` of the selected coefficients, a block (or the
        resolved candidates of a cut) at a time, in the blocks' order; ``tiers``: also the .clw tier of each."""
        counts = []
        for gi, (wavelet, channels) in enumerate(self.groups()):
            plan = self._plan(wavelet, gi, self.focus)
            candidates = []
            counts.append(0)
            tasks = self._tasks(_select_block, wavelet, channels, plan)
            for kept, cand in stream(client, tasks, desc=f"{wavelet.name} selection", progress_bar=self.progress_bar):
                counts[-1] += len(kept[0])
                if len(kept[0]):
                    yield (gi,) + (kept if tiers else kept[:2])
                if cand is not None and len(cand[0]):
                    candidates.append(cand)
            for c, rule in enumerate(plan.rules):
                if rule.bin is None:
                    continue
                mine = [x for x in candidates if x[4] == c]
                if not mine:
                    continue
                pos, values, tier, imp = (np.concatenate([x[i] for x in mine], axis=-1) for i in range(4))
                by_position = np.argsort(pos)  # _top breaks ties by index: by position, not by arrival order
                chosen = by_position[_top(imp[by_position], rule.take)]
                counts[-1] += len(chosen)
                out = (pos[chosen], values[:, chosen], tier[chosen])
                yield (gi,) + (out if tiers else out[:2])
        self.kept = max(counts)

    def content_blocks(self, client):
        """Yield ``(slices, bool block)`` of the content mask, a source block at a time (sent packed)."""
        import dask

        mask = content_of(self.volume.data)
        starts = [np.cumsum((0,) + c) for c in mask.chunks]
        tasks = []
        for index, block in np.ndenumerate(mask.to_delayed()):
            box = tuple(slice(int(s[i]), int(s[i + 1])) for s, i in zip(starts, index))
            tasks.append(dask.delayed(_pack)(block, box))
        for box, packed in stream(client, tasks, desc="content mask", progress_bar=self.progress_bar):
            shape = tuple(s.stop - s.start for s in box)
            yield box, np.unpackbits(packed, count=int(np.prod(shape))).reshape(shape).view(bool)

    def compute(self) -> WaveletVolume:
        """Gather the selected coefficients into an in-memory :class:`WaveletVolume` (it must fit: threshold
        first); equal to the in-memory model's (docs/chunked.md §2-3)."""
        groups = self.groups()
        parts = {gi: [] for gi in range(len(groups))}
        mask = ContentMask(self.shape)
        with client_for(self.scheduler) as client:
            for box, block in self.content_blocks(client):
                mask.put([s.start for s in box], block)
            for gi, positions, values in self.selected(client):
                parts[gi].append((positions, values))
        out = [ChannelGroup.gathered(wavelet, channels, band_layout(wavelet, self.shape, self.levels), parts[gi])
               for gi, (wavelet, channels) in enumerate(groups)]
        return WaveletVolume(self.shape, self.spacing, self.origin, self.levels, out, self.channels,
                             focus=self.focus, transfer_function=self.transfer_function, content=self.content,
                             content_mask=mask, subtracted=self.subtracted, obliquity=self.obliquity,
                             value_range=self.value_range, unit=self.unit, photo=self.photo, provenance=self.provenance,
                             modality=self.modality, noise_sigma=self.noise_sigma)

    def save(self, path, overwrite=False, quantise=None) -> Path:
        """Stream the selected coefficients into a ``.clw`` file (docs/chunked.md §4), in bounded memory;
        ``quantise`` as :meth:`WaveletVolume.save` (a bound only)."""
        return WaveletVolume.file_format[1](self, path, overwrite, quantise)


# ---------------------------------------------------------------- the graph


def level_stacks(source, wavelet: SplineWavelet, levels: int, bands, frame):
    """Yield ``(level, stack, starts)`` for the levels that hold coefficients: ``stack`` a Dask array
    (8, nz, ny, nx, C) of the level's subbands in :data:`KEYS` order (1, ...) of the voxels for
    ``levels = 0``), ``starts`` per axis the band index where each block begins.

    Level m transforms level m-1's approximation (the volume for m = 1) block by block: a block with
    input [a, b) per axis gives the coefficients k in [a/2, b/2) (to the band's end for the last block),
    which depend on the input [a + 2 - L, b) (output k reads x[2k + 2 - L .. 2k + 1], L the filter
    length), so each block takes L - 2 samples of halo from its lower neighbours (:func:`_with_halo`)
    and starts at an even a: then PyWavelets (mode 'zero') on the block gives bit for bit the
    coefficients of the whole.  ``frame`` (shape, spacing): the first level's blocks check their voxels against it
    (:func:`~clwave.model.transform.check_coefficients`; at 0 levels the coefficients are the voxels, checked there).
    """
    if levels == 0:
        x = _even_chunks(source, 0)
        yield 0, x[None], [np.cumsum((0,) + c)[:-1] for c in x.chunks[:3]]
        return
    import dask.array as da

    halo = wavelet.pywt.dec_len - 2
    x = source
    for level in range(1, levels + 1):
        x = _even_chunks(x, halo)
        n_out = bands[1 + 7 * (levels - level)].shape  # every subband of a level has one shape
        starts = [np.cumsum((0,) + c)[:-1] for c in x.chunks[:3]]
        out_chunks = [tuple(np.diff(np.append(s // 2, n))) for s, n in zip(starts, n_out)]
        stack = da.map_blocks(_transform_block, _with_halo(x, halo) if halo else x, starts=starts, halo=halo,
                              n_out=n_out, order=wavelet.order, frame=frame if level == 1 else None, new_axis=0,
                              dtype=np.float32,
                              chunks=((8,),) + tuple(out_chunks) + (x.chunks[3],), meta=np.empty((0,) * 5, np.float32))
        yield level, stack, [s // 2 for s in starts]
        x = stack[0].map_blocks(np.copy)  # a copy: a view would keep the whole stack alive for the next level


def _with_halo(x, halo):
    """``x`` (z, y, x, C) with ``halo`` samples before each block along z, y and x, cut from the lower
    neighbours as copies: a chunk is freed as soon as its own block and its halos are taken (Dask's
    ``overlap`` slices are views, which keep every neighbour whole until its last user has run: a
    wavefront of whole chunks across the volume)."""
    import dask
    import dask.array as da

    blocks = x.to_delayed(optimize_graph=False)[..., 0]
    out = np.empty(blocks.shape + (1,), dtype=object)
    for index in np.ndindex(blocks.shape):
        lows = [(-1, 0) if i else (0,) for i in index]
        pieces = {}
        for offset in product(*lows):
            neighbour = blocks[tuple(i + o for i, o in zip(index, offset))]
            cut = tuple(slice(-halo, None) if o else slice(None) for o in offset)
            pieces[offset] = neighbour if not any(offset) else dask.delayed(_copy)(neighbour, cut)
        nested = [[[[pieces[(a, b, c)]] for c in lows[2]] for b in lows[1]] for a in lows[0]]  # as deep as (z, y, x, c)
        shape = tuple(x.chunks[a][i] + (halo if i else 0) for a, i in enumerate(index)) + (x.shape[3],)
        out[index + (0,)] = da.from_delayed(dask.delayed(np.block)(nested), shape, dtype=x.dtype)
    return da.block(out.tolist())


def _copy(block, cut):
    return block[cut].copy()


def _transform_block(block, starts, halo, n_out, order, frame=None, block_id=None):
    """The 8 subbands (8, ...) of the block ``block_id`` of a level's input, ``block`` with its halo; ``frame``:
    the input is the voxels, checked as the in-memory transform checks them."""
    if frame is not None:
        check_coefficients(block, frame)
    index = block_id[1:4]  # the output's block: (subband, z, y, x, channel)
    a = [int(s[i]) for s, i in zip(starts, index)]
    lo_halo = [min(halo, ai) for ai in a]  # no halo before the first block (boundary 'none')
    first = [(ai - h) // 2 for ai, h in zip(a, lo_halo)]  # the band index of the block's output 0
    ends = [int(s[i + 1]) // 2 if i + 1 < len(s) else n for s, i, n in zip(starts, index, n_out)]
    coeffs = pywt.dwtn(block, SplineWavelet(order).pywt, mode="zero", axes=(0, 1, 2))
    box = tuple(slice(ai // 2 - f, e - f) for ai, f, e in zip(a, first, ends)) + (slice(None),)
    return np.stack([coeffs[key][box] for key in KEYS])


def _even_chunks(x, halo):
    """``x`` rechunked so that every block but the last per axis has an even edge of at least ``halo``, the
    last at least ``halo``, with at least :data:`MIN_BLOCK_VOXELS` voxels a block where the volume allows,
    and at most :data:`MAX_BLOCKS` blocks (docs/chunked.md §2).  Larger chunks are kept: cutting them
    (a rechunk) costs more memory than it saves."""
    shape = x.shape[:3]
    edges = [min(n, max(halo, 2, e + e % 2)) for e, n in zip((max(c) for c in x.chunks[:3]), shape)]

    def blocks(edges):
        return np.prod([-(-n // e) for e, n in zip(edges, shape)])

    while (np.prod(edges) < MIN_BLOCK_VOXELS or blocks(edges) > MAX_BLOCKS) and \
            any(e < n for e, n in zip(edges, shape)):
        edges = [min(n, 2 * e) for e, n in zip(edges, shape)]
    chunks = []
    for e, n in zip(edges, shape):
        e += e % 2
        full, rest = divmod(n, e)
        axis = [e] * full + ([rest] if rest else [])
        if len(axis) > 1 and axis[-1] < halo:  # too short to lend its halo: joined with its neighbour
            axis[-2:] = [axis[-2] + axis[-1]]
        chunks.append(tuple(axis) if axis else (n,))
    chunks = tuple(chunks) + (x.chunks[3],)
    return x if chunks == x.chunks else x.rechunk(chunks)


# ---------------------------------------------------------------- block tasks


class _Entries:
    """The coefficients of one subband of a block: ``values`` (C, n) and ``importance`` (n,) of the live
    ones (every one with ``live_only`` false), their class, and on demand their positions and tiers (the
    arrays a pass needs only for the coefficients it keeps)."""

    def __init__(self, stack, level, key, offsets, plan, live_only):
        self.band, self.plan = plan.band(level, key), plan
        self.cls = APPROX if key == "aaa" and level == plan.levels else DETAIL
        coeffs = stack[KEYS.index(key) if level else 0]
        self.shape, self.offsets = coeffs.shape[:3], np.array(offsets)[:, None]
        values = np.moveaxis(coeffs, 3, 0).reshape(coeffs.shape[3], -1)
        check_coefficients(values, plan.frame[:2] if plan.levels == 0 else None)  # 0 levels: the voxels
        self.flat = np.flatnonzero(np.any(values != 0, axis=0)) if live_only else np.arange(values.shape[1])
        self.values = values[:, self.flat] if live_only else values
        index = None if plan.focus is None else self.index(slice(None))
        self.importance = band_importance(plan.wavelet, self.band, self.values, index, plan.focus, plan.frame,
                                          plan.noise)

    def index(self, sel):
        """Band indices (n, 3) of the coefficients ``sel`` selects."""
        return (np.array(np.unravel_index(self.flat[sel], self.shape)) + self.offsets).T

    def positions(self, sel):
        return self.band.start + np.ravel_multi_index(self.index(sel).T, self.band.shape).astype(np.int64)

    def tiers(self, sel):
        """The .clw tiers, by the importance without a focus or noise (docs/chunked.md §4)."""
        if self.plan.focus is None and self.plan.noise is None:
            return tiers_of(self.importance[sel])
        values = self.values[:, sel]
        return tiers_of(band_importance(self.plan.wavelet, self.band, values, None, None, self.plan.frame))


def _entries(stack, level, offsets, plan, live_only=True):
    """:class:`_Entries` of each subband present in a block of ``level``."""
    keys = ["aaa"] if level == 0 else KEYS if level == plan.levels else KEYS[1:]
    return (_Entries(stack, level, key, offsets, plan, live_only) for key in keys)


def _finest_block(stack, level, offsets, plan, bins=None):
    """Per channel, the histogram of the non-zero |d| of the block's part of the interior of the finest diagonal
    band (:mod:`~clwave.model.noise`), (C, 2^16); with ``bins``, those |d| in each channel's bin."""
    band, inside = plan.band(1, "ddd"), noise.interior(plan.wavelet, plan.frame[0])
    box = []
    for axis, cut in enumerate(inside):
        start, stop, _ = cut.indices(band.shape[axis])
        n = stack.shape[1 + axis]
        box.append(slice(min(n, max(0, start - offsets[axis])), max(0, min(n, stop - offsets[axis]))))
    values = stack[KEYS.index("ddd")][tuple(box)]
    mags = [noise.magnitudes(values[..., c]) for c in range(values.shape[-1])]
    if bins is None:
        return np.stack([noise.histogram(m) for m in mags])
    return [m[noise.bins_of(m) == b] for m, b in zip(mags, bins)]


def _histogram_block(stack, level, offsets, plan):
    """Per class, the non-empty histogram bins ``(bins, counts)`` of the block's live importances."""
    per_class = [[], []]
    for entries in _entries(stack, level, offsets, plan):
        per_class[entries.cls].append(importance_keys(entries.importance) >> BIN_SHIFT)
    out = []
    for keys in per_class:
        counts = np.bincount(np.concatenate(keys), minlength=1) if keys else np.zeros(1, np.int64)
        bins = np.flatnonzero(counts)
        out.append((bins, counts[bins]))
    return out


def _select_block(stack, level, offsets, plan):
    """``(kept (positions, values, tiers), candidates)`` of a block under the plan's rules; candidates
    ``(positions, values, tiers, importance, class)`` of a cut's bin, or None."""
    kept, cands = [], []
    for entries in _entries(stack, level, offsets, plan, live_only=not _keeps_every(plan.rules)):
        take, maybe = (np.flatnonzero(m) for m in plan.rules[entries.cls].kept(entries.importance))
        kept.append((entries.positions(take), entries.values[:, take], entries.tiers(take)))
        if len(maybe):
            cands.append((entries.positions(maybe), entries.values[:, maybe], entries.tiers(maybe),
                          entries.importance[maybe], entries.cls))
    joined = tuple(np.concatenate([k[i] for k in kept], axis=-1) for i in range(3))
    if not cands:
        return joined, None
    classes = {c[4] for c in cands}
    assert len(classes) == 1  # a cut lies in one class
    return joined, tuple(np.concatenate([c[i] for c in cands], axis=-1) for i in range(4)) + (classes.pop(),)


def _pack(block, box):
    return box, np.packbits(np.asarray(block, dtype=bool).reshape(-1))


def _keeps_every(rules) -> bool:
    """True for the rules of an unthresholded model: every position, zeros too."""
    return all(rule.every for rule in rules)


def _cut(hist, budget) -> tuple:
    """``(approximation rule, detail rule)`` keeping ``budget`` coefficients as :meth:`WaveletVolume.threshold`
    does: the live approximation first, then details by importance; each cut at the bin the histogram
    places it in."""
    n_approx = int(hist[APPROX].sum())
    if budget <= n_approx:
        return _bin_rule(hist[APPROX], budget), Rule(none=True)
    return Rule(), _bin_rule(hist[DETAIL], budget - n_approx)


def _bin_rule(hist, count) -> Rule:
    above = np.cumsum(hist[::-1])[::-1]  # above[b]: coefficients in bins >= b
    if count >= above[0]:
        return Rule()
    b = int(np.flatnonzero(above >= count)[-1])
    return Rule(bin=b, take=count - int(above[b] - hist[b]))


WaveletVolume.chunked_model = ChunkedWaveletVolume
