"""WaveletVolume: the sparse B-spline wavelet model both renderers stand on.

A volume's channels are decomposed with the CDF(j, j) spline wavelets
(:mod:`clwave.bspline`) by ``pywt.wavedecn(mode="zero")``, whose coefficients
are exactly the real-line transform of the zero-extended data (MATH.md §3.3).
The continuous model of one channel of order j (MATH.md §4, paper eq. 12-13) is

    f(x) = sum_bands sum_k c_k 2^{-3m/2} P_key(2^{-m}(x - o_m) - k)

in fine-voxel coordinates ``x_a = (p_a - origin_a)/d_a + (n_a - 1)/2 + j/2``
(CONVENTIONS.md), zero outside its support.  It is evaluated directly from the
closed-form bases, without any inverse transform.

Channels that share a wavelet form one *group* with one index set
(CONVENTIONS.md: thresholding keeps coefficient positions shared by all
channels).  A group stores its coefficients sparsely as global *positions*
into the concatenation of its bands (coarsest approximation first, then the
details from coarse to fine) and a ``(K, channels)`` float32 value table, kept
in ascending position order; importance order is derived on demand.
"""

from __future__ import annotations

import json
import os
import warnings
import zipfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import cached_property
from itertools import product
from pathlib import Path

import numpy as np
import pywt
from scipy.linalg import solve_banded
from scipy.ndimage import correlate1d
from scipy.signal import upfirdn

from .bspline import SplineWavelet, max_levels, wavelet_for
from .errors import FileFormatError, InputError
from .files import write_atomic
from .progress import progress
from .volume import Volume

FILE_FORMAT = "clwave-wavelet-volume"
FILE_VERSION = 1
KEYS = ["".join(k) for k in product("ad", repeat=3)]  # 'aaa', 'aad', ... in array-axis order


@dataclass(frozen=True)
class Band:
    """One subband: level m (0 = the voxels' own B-splines), key in (z, y, x) letter order."""

    level: int
    key: str
    shape: tuple
    start: int  # first global position of this band in its group

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    @property
    def code(self) -> int:
        """Subband code: bit 0 set for 'd' (psi) along x, bit 1 along y, bit 2 along z."""
        return sum(1 << (2 - a) for a, ch in enumerate(self.key) if ch == "d")


@dataclass
class CoefficientTable:
    """Coefficients of one group in importance order, ready for upload.

    ``index`` is the pywt index in array order ``(k_z, k_y, k_x)``; ``key_code`` is the
    band's :attr:`Band.code`.
    """

    level: np.ndarray       # (K,) int8
    key_code: np.ndarray    # (K,) uint8
    index: np.ndarray       # (K, 3) int32
    values: np.ndarray      # (K, C) float32
    importance: np.ndarray  # (K,) float32


class ChannelGroup:
    """Channels sharing one wavelet, bands and index set."""

    def __init__(self, wavelet: SplineWavelet, channels, bands, positions, values):
        self.wavelet = wavelet
        self.channels = tuple(channels)
        self.bands = list(bands)
        self.positions = positions  # (K,) int64 ascending, or None for every position
        self.values = values        # (C, K) float32, channel-major for fast per-channel work

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
        """Band number and (k_z, k_y, k_x) index of global positions."""
        starts = np.array([b.start for b in self.bands], dtype=np.int64)
        band_no = np.searchsorted(starts, positions, side="right") - 1
        index = np.empty((len(positions), 3), dtype=np.int64)
        for b_no, band in enumerate(self.bands):
            sel = band_no == b_no
            if sel.any():
                index[sel] = np.column_stack(np.unravel_index(positions[sel] - band.start, band.shape))
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

    def __init__(self, shape, spacing, origin, levels, groups, channels, *, interpolate=False,
                 focus=None, transfer_function=None):
        self.shape = tuple(int(s) for s in shape)
        self.spacing = tuple(float(s) for s in spacing)
        self.origin = tuple(float(o) for o in origin)
        self.levels = int(levels)
        self.groups = list(groups)
        self.channels = int(channels)
        self.interpolate = bool(interpolate)
        self.focus = focus  # ((x, y, z), sigma) used by threshold, or None
        self.transfer_function = transfer_function  # JSON-safe dict, or None

    # ------------------------------------------------------------------ build
    @classmethod
    def from_volume(cls, volume: Volume, wavelet="cubic", levels=3, *, interpolate=False,
                    transfer_function=None, progress_bar=None) -> "WaveletVolume":
        """Decompose every channel of ``volume`` (paper Fig. 1).

        Parameters
        ----------
        wavelet : str or sequence of str
            'haar', 'linear', 'quadratic' or 'cubic'; one per channel to mix orders
            (e.g. cubic RGB with Haar opacity, paper Fig. 14).
        levels : int
            0 (the voxels' own B-splines) up to ``floor(log2(min axis)) - 1``.
        interpolate : bool
            False (default): the samples are the B-spline coefficients (paper eq. 8,
            approximating, mass preserving).  True: prefilter so the model passes
            through the samples (MATH.md §1).
        transfer_function : TransferFunction or dict, optional
            Stored with the volume (and in ``.clw`` files) to record how it was classified.
        """
        if not isinstance(volume, Volume):
            volume = Volume(volume)
        wavelets = _channel_wavelets(wavelet, volume.channels)
        levels = _check_levels(levels, volume.shape)
        tf = transfer_function.to_dict() if hasattr(transfer_function, "to_dict") else transfer_function
        groups = []
        for wav in dict.fromkeys(wavelets):
            chans = [c for c, w in enumerate(wavelets) if w == wav]
            groups.append(_decompose_group(volume, wav, chans, levels, interpolate, progress_bar))
        return cls(volume.shape, volume.spacing, volume.origin, levels, groups, volume.channels,
                   interpolate=interpolate, transfer_function=tf)

    # ------------------------------------------------------------- properties
    @property
    def wavelets(self) -> tuple:
        """Wavelet name of each channel."""
        names = [None] * self.channels
        for g in self.groups:
            for c in g.channels:
                names[c] = g.wavelet.name
        return tuple(names)

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
        extension, MATH.md §3.3), so its compression is slightly negative.
        """
        return 1.0 - float(np.mean([g.kept for g in self.groups])) / self.n_voxels

    def __repr__(self):
        return (f"WaveletVolume(shape={self.shape}, wavelets={self.wavelets}, levels={self.levels}, "
                f"kept={self.kept}, compression={self.compression:.4f})")

    # ----------------------------------------------------------- importance
    def _importance(self, group: ChannelGroup) -> np.ndarray:
        """|c| * ||basis|| (max over the group's channels), times the focus weight.

        One value per kept position of the group, in its (ascending) position order.
        """
        imp = np.abs(group.values).max(axis=0)
        for band, sl in zip(group.bands, group.band_slices()):
            imp[sl] *= np.prod([group.wavelet.norm(letter) for letter in band.key])
        if self.focus is not None:
            centre, sigma = self.focus
            world = self._support_centres(group, *group.locate(group.all_positions()))
            imp *= np.exp(-np.sum((world - np.asarray(centre)) ** 2, axis=1) / (2.0 * sigma ** 2))
        return imp

    def _support_centres(self, group, band_no, index) -> np.ndarray:
        """World (x, y, z) centres of the basis supports (MATH.md §6: X = o + 2^m (k + c0))."""
        wav = group.wavelet
        fine = np.empty(index.shape, dtype=np.float64)
        for b_no, band in enumerate(group.bands):
            sel = band_no == b_no
            if not sel.any():
                continue
            for axis, letter in enumerate(band.key):
                scale = 2.0 ** band.level
                fine[sel, axis] = (wav.offset(letter, band.level)
                                   + scale * (index[sel, axis] + wav.support(letter) / 2.0))
        return self._fine_to_world(fine, wav.order)

    def _fine_to_world(self, fine_zyx, order) -> np.ndarray:
        n = np.array(self.shape, float)
        d = np.array(self.spacing, float)
        world_zyx = (fine_zyx - order / 2.0 - (n - 1) / 2.0) * d
        return world_zyx[:, ::-1] + np.asarray(self.origin)

    def _world_to_fine(self, points_xyz, order) -> np.ndarray:
        p = np.asarray(points_xyz, float)[:, ::-1] - np.asarray(self.origin)[::-1]
        n = np.array(self.shape, float)
        d = np.array(self.spacing, float)
        return p / d + (n - 1) / 2.0 + order / 2.0

    # ------------------------------------------------------------- threshold
    def threshold(self, keep=None, threshold=None, focus=None) -> "WaveletVolume":
        """Keep the most important coefficient positions (CONVENTIONS.md "Thresholding").

        Parameters
        ----------
        keep : float in (0, 1]
            Keep ``round(keep * number_of_voxels)`` positions: the coarsest
            approximation band first (its largest coefficients if the budget is
            smaller), then details by ``|c| * ||basis||`` (max over channels).
        threshold : float >= 0
            Keep the approximation band and every detail whose importance exceeds it.
        focus : ((x, y, z), sigma), optional
            Local level of detail (paper Fig. 12/13): importance is weighted by
            ``exp(-d^2 / 2 sigma^2)``, d the world distance from the focus to the
            centre of the basis support, so detail survives near the focus.
        """
        if (keep is None) == (threshold is None):
            raise InputError("give exactly one of keep= (fraction of voxels) or threshold= (importance)")
        if keep is not None and not (np.isfinite(keep) and 0 < keep <= 1):
            raise InputError(f"keep={keep} must be a fraction in (0, 1]")
        if threshold is not None and not (np.isfinite(threshold) and threshold >= 0):
            raise InputError(f"threshold={threshold} must be a finite number >= 0")
        out = WaveletVolume(self.shape, self.spacing, self.origin, self.levels, [], self.channels,
                            interpolate=self.interpolate, focus=_check_focus(focus),
                            transfer_function=self.transfer_function)
        budget = None if keep is None else max(1, int(round(keep * self.n_voxels)))
        for g in self.groups:
            positions = g.all_positions()
            imp = out._importance(g)
            n_approx = g.band_slices()[0].stop  # the approximation band ranks first
            if budget is None:
                chosen = np.concatenate([np.arange(n_approx), n_approx + np.flatnonzero(imp[n_approx:] > threshold)])
            elif budget <= n_approx:
                chosen = _top(imp[:n_approx], budget)
            else:
                rest = min(budget - n_approx, len(positions) - n_approx)
                chosen = np.concatenate([np.arange(n_approx), n_approx + _top(imp[n_approx:], rest)])
            chosen.sort()
            out.groups.append(ChannelGroup(g.wavelet, g.channels, g.bands, positions[chosen],
                                           np.ascontiguousarray(g.values[:, chosen])))
        return out

    # ------------------------------------------------------- upload views
    def ranked(self, group: int = 0) -> CoefficientTable:
        """The group's coefficients sorted by importance (approximation band first)."""
        return self._ranked[group]

    @cached_property
    def _ranked(self) -> list:
        tables = []
        for g in self.groups:
            positions = g.all_positions()
            imp = self._importance(g)
            approx = positions < g.bands[0].size
            order = np.lexsort((positions, -imp, ~approx))  # approx first, then importance, ties by position
            band_no, index = g.locate(positions[order])
            levels = np.array([b.level for b in g.bands], dtype=np.int8)
            codes = np.array([b.code for b in g.bands], dtype=np.uint8)
            tables.append(CoefficientTable(levels[band_no], codes[band_no], index.astype(np.int32),
                                           np.ascontiguousarray(g.values[:, order].T),
                                           imp[order].astype(np.float32)))
        return tables

    def bands(self, group: int = 0):
        """Per level and subband: ``(Band, index (K, 3) int32, values (K, C))``, by importance."""
        table, g = self.ranked(group), self.groups[group]
        out = []
        for band in g.bands:
            sel = (table.level == band.level) & (table.key_code == band.code)
            out.append((band, table.index[sel], table.values[sel]))
        return out

    # -------------------------------------------------------- evaluation
    def evaluate(self, points) -> np.ndarray:
        """The continuous model at world points (N, 3) as (x, y, z); returns (N, C)."""
        return self._evaluate(points, derivative=False)

    def gradient(self, points) -> np.ndarray:
        """Analytic gradient (paper eq. 14-16, MATH.md §4) at world points: (N, C, 3) as d/dx, d/dy, d/dz."""
        return self._evaluate(points, derivative=True)

    def _evaluate(self, points, derivative):
        pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise InputError(f"points must have shape (N, 3) as (x, y, z), got {np.shape(points)}")
        n_pts = len(pts)
        out = np.zeros((n_pts, self.channels, 3) if derivative else (n_pts, self.channels))
        for g, bands in zip(self.groups, self._dense):
            fine = self._world_to_fine(pts, g.wavelet.order)  # (N, 3) in (z, y, x)
            acc = np.zeros(out.shape[:1] + (len(g.channels),) + out.shape[2:])
            for band, coeffs in zip(g.bands, bands):
                acc += _band_sum(g.wavelet, band, coeffs, fine, derivative)
            if derivative:
                acc = acc[..., ::-1] / np.asarray(self.spacing)[::-1]  # fine (z,y,x) -> world (x,y,z)
            out[:, list(g.channels)] = acc
        return out

    @cached_property
    def _dense(self) -> list:
        return [g.dense_bands() for g in self.groups]

    # ------------------------------------------------------ reconstruction
    def fine_coefficients(self, group: int = 0):
        """Real-line synthesis down to level 0: the fine-level B-spline coefficients.

        Returns ``(coeffs, start)``: ``coeffs`` (Z, Y, X, C) float64 with
        ``coeffs[i, j, k]`` the coefficient of ``N_j(x - (start + (i, j, k)))``.
        ``start`` can be negative: after thresholding the model reaches beyond
        the voxel grid, and nothing is cropped here.
        """
        g = self.groups[group]
        return _synthesize(g.wavelet, g.bands, self._dense[group])

    def reconstruct(self) -> Volume:
        """The voxel data the model represents, as a float32 :class:`Volume`.

        For the approximating model these are the fine B-spline coefficients on the
        voxel grid (``pywt.waverecn``, which equals the real-line synthesis there);
        with ``interpolate=True`` the model's values at the voxel centres.
        """
        data = np.zeros(self.shape + (self.channels,), dtype=np.float32)
        for gi, g in enumerate(self.groups):
            if self.interpolate:  # needs the coefficients just beyond the grid too
                coeffs, start = _apply_sampling_filter(*self.fine_coefficients(gi), g.wavelet)
                data[..., list(g.channels)] = _crop(coeffs, start, self.shape)
                continue
            for slot, channel in enumerate(g.channels):
                data[..., channel] = _waverecn(g, self._dense[gi], slot, self.shape, self.levels)
        return Volume(data if self.channels > 1 else data[..., 0], self.spacing, self.origin)

    # ------------------------------------------------------------- files
    def save(self, path, overwrite=False) -> Path:
        """Write a ``.clw`` file (zip of npy): exact float32 values, bit-mask indices (deflated).

        Refuses to replace an existing file unless ``overwrite``; writes atomically.
        """
        header = dict(format=FILE_FORMAT, version=FILE_VERSION, shape=self.shape,
                      spacing=self.spacing, origin=self.origin, levels=self.levels,
                      channels=self.channels, interpolate=self.interpolate,
                      focus=None if self.focus is None else [list(self.focus[0]), self.focus[1]],
                      transfer_function=self.transfer_function,
                      groups=[dict(wavelet=g.wavelet.order, channels=list(g.channels), kept=g.kept)
                              for g in self.groups])
        arrays = {"header": np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)}
        for gi, g in enumerate(self.groups):
            mask = np.zeros(g.total, dtype=bool)
            mask[g.all_positions()] = True
            arrays[f"mask{gi}"] = np.packbits(mask)
            arrays[f"values{gi}"] = np.ascontiguousarray(g.values, dtype=np.float32)
        return write_atomic(path, lambda fh: np.savez_compressed(fh, **arrays), overwrite)

    @classmethod
    def open(cls, path) -> "WaveletVolume":
        """Read a ``.clw`` file written by :meth:`save`."""
        path = Path(path)
        if not path.is_file():
            raise FileFormatError(f"{path} does not exist or is not a file")
        try:
            with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as npz:
                header = json.loads(bytes(npz["header"]).decode())
                arrays = {k: npz[k] for k in npz.files if k != "header"}
        except (OSError, ValueError, KeyError, zipfile.BadZipFile, EOFError, json.JSONDecodeError) as exc:
            raise FileFormatError(f"cannot read {path} as a .clw file ({type(exc).__name__}: "
                                  f"{str(exc).splitlines()[0] if str(exc) else 'no detail'}); "
                                  "the file may be truncated or corrupt") from None
        if header.get("format") != FILE_FORMAT or header.get("version") != FILE_VERSION:
            raise FileFormatError(f"{path} is not a clwave v{FILE_VERSION} wavelet volume file")
        try:
            shape, levels = tuple(header["shape"]), int(header["levels"])
            groups = []
            for gi, gh in enumerate(header["groups"]):
                wav = SplineWavelet(int(gh["wavelet"]))
                bands = _band_layout(wav, shape, levels)
                total = bands[-1].start + bands[-1].size
                mask = np.unpackbits(arrays[f"mask{gi}"], count=total).astype(bool)
                values = arrays[f"values{gi}"]
                if values.shape != (len(gh["channels"]), int(mask.sum())) or values.dtype != np.float32:
                    raise ValueError(f"group {gi}: values {values.shape} do not match the index mask")
                positions = None if mask.all() else np.flatnonzero(mask)
                groups.append(ChannelGroup(wav, gh["channels"], bands, positions, values))
            focus = header["focus"]
            return cls(shape, header["spacing"], header["origin"], levels, groups, header["channels"],
                       interpolate=header["interpolate"],
                       focus=None if focus is None else (tuple(focus[0]), float(focus[1])),
                       transfer_function=header["transfer_function"])
        except (KeyError, ValueError, TypeError, InputError) as exc:
            raise FileFormatError(f"{path} is inconsistent ({exc}); the file may be corrupt") from None


# ---------------------------------------------------------------- helpers


def _channel_wavelets(wavelet, channels) -> list:
    if isinstance(wavelet, (list, tuple)):
        if len(wavelet) != channels:
            raise InputError(f"{len(wavelet)} wavelets given for {channels} channel(s); give one, "
                             "or one per channel")
        return [wavelet_for(w) for w in wavelet]
    return [wavelet_for(wavelet)] * channels


def _check_levels(levels, shape) -> int:
    top = max_levels(shape)
    if isinstance(levels, bool) or not isinstance(levels, (int, np.integer)) or not 0 <= levels <= top:
        raise InputError(f"levels={levels!r} is not possible for shape {shape}: use an integer "
                         f"from 0 to {top} (floor(log2(shortest axis)) - 1)")
    return int(levels)


def _check_focus(focus):
    if focus is None:
        return None
    try:
        centre, sigma = focus
        centre = tuple(float(c) for c in centre)
        sigma = float(sigma)
    except (TypeError, ValueError):
        raise InputError("focus must be ((x, y, z), sigma) in world units") from None
    if len(centre) != 3 or not np.all(np.isfinite(centre)) or not (np.isfinite(sigma) and sigma > 0):
        raise InputError(f"focus {focus!r} needs a finite (x, y, z) centre and sigma > 0")
    return centre, sigma


def _top(importance, count) -> np.ndarray:
    """Indices of the ``count`` largest values (exact count)."""
    if count >= len(importance):
        return np.arange(len(importance))
    if count <= 0:
        return np.zeros(0, dtype=np.int64)
    return np.argpartition(-importance, count - 1)[:count]


def _band_layout(wavelet: SplineWavelet, shape, levels) -> list:
    """Bands of a pywt mode='zero' decomposition, coarsest approximation first."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Level value of .* is too high")
        shapes = pywt.wavedecn_shapes(shape, wavelet.pywt, mode="zero", level=levels)
    layout = [(levels, "aaa", tuple(shapes[0]))]
    for i, detail in enumerate(shapes[1:]):
        m = levels - i
        layout += [(m, key, tuple(detail[key])) for key in KEYS[1:]]
    bands, start = [], 0
    for m, key, shp in layout:
        bands.append(Band(m, key, shp, start))
        start += int(np.prod(shp))
    return bands


def _prefilter(data: np.ndarray, wavelet: SplineWavelet) -> np.ndarray:
    """B-spline coefficients whose model interpolates ``data`` at voxel centres (zero extension)."""
    w = _sampling_kernel(wavelet)
    half = len(w) // 2
    if half == 0:
        return data
    out = data.astype(np.float64)
    for axis in range(3):
        n = out.shape[axis]
        ab = np.zeros((2 * half + 1, n))
        for row in range(2 * half + 1):
            ab[row] = w[row]  # symmetric Toeplitz band
        moved = np.moveaxis(out, axis, 0).reshape(n, -1)
        out = np.moveaxis(solve_banded((half, half), ab, moved).reshape(np.moveaxis(out, axis, 0).shape), 0, axis)
    return out


def _sampling_kernel(wavelet: SplineWavelet) -> np.ndarray:
    """Weights w_s with f(i + j/2) = sum_s w_s c_{i-s} (MATH.md §1)."""
    j = wavelet.order
    half = (j - 1) // 2
    s = np.arange(-half, half + 1)
    return wavelet.phi(s + j / 2.0)


def _apply_sampling_filter(coeffs, start, wavelet):
    w = _sampling_kernel(wavelet)
    half = len(w) // 2
    if half == 0:
        return coeffs, start
    padded = np.pad(coeffs, [(half, half)] * 3 + [(0, 0)])
    for axis in range(3):
        padded = correlate1d(padded, w, axis=axis, mode="constant")
    return padded, tuple(s - half for s in start)


def _crop(coeffs, start, shape) -> np.ndarray:
    """The part of an offset array on the voxel grid [0, n) per axis (zeros where absent)."""
    out = np.zeros(tuple(shape) + coeffs.shape[3:], dtype=coeffs.dtype)
    src, dst = [], []
    for s, n, size in zip(start, shape, coeffs.shape[:3]):
        lo, hi = max(0, s), min(n, s + size)
        if hi <= lo:
            return out
        src.append(slice(lo - s, hi - s))
        dst.append(slice(lo, hi))
    out[tuple(dst)] = coeffs[tuple(src)]
    return out


def _decompose_group(volume, wavelet, channels, levels, interpolate, progress_bar) -> ChannelGroup:
    bands = _band_layout(wavelet, volume.shape, levels)
    total = bands[-1].start + bands[-1].size
    values = np.empty((len(channels), total), dtype=np.float32)

    def one(slot_channel):
        slot, channel = slot_channel
        data = volume.channel(channel)
        if interpolate:
            data = _prefilter(data, wavelet).astype(np.float32)
        if levels == 0:
            values[slot] = data.ravel()
            return
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="Level value of .* is too high")
            coeffs = pywt.wavedecn(data, wavelet.pywt, mode="zero", level=levels)
        parts = [coeffs[0]] + [detail[key] for detail in coeffs[1:] for key in KEYS[1:]]
        for band, part in zip(bands, parts):
            values[slot, band.start:band.start + band.size] = part.ravel()

    jobs = list(enumerate(channels))
    with ThreadPoolExecutor(max_workers=min(len(jobs), os.cpu_count() or 1)) as pool:
        list(progress(pool.map(one, jobs), total=len(jobs), desc=f"{wavelet.name} transform",
                      enabled=progress_bar))
    return ChannelGroup(wavelet, channels, bands, None, values)


def _waverecn(group, dense, slot, shape, levels) -> np.ndarray:
    """One channel back on the voxel grid through PyWavelets."""
    if levels == 0:
        return dense[0][..., slot]
    coeffs = [dense[0][..., slot]]
    for i in range(levels):
        coeffs.append({b.key: arr[..., slot] for b, arr in zip(group.bands[1 + 7 * i:8 + 7 * i],
                                                             dense[1 + 7 * i:8 + 7 * i])})
    out = pywt.waverecn(coeffs, group.wavelet.pywt, mode="zero")
    return out[tuple(slice(0, n) for n in shape)]


def _band_sum(wavelet, band, coeffs, fine_zyx, derivative) -> np.ndarray:
    """Sum of one band's basis functions at fine points (N, 3), (N, C) or (N, C, 3) in (z, y, x)."""
    m, scale = band.level, 2.0 ** band.level
    n_pts = len(fine_zyx)
    axis_vals, axis_ders, axis_idx = [], [], []
    for axis, letter in enumerate(band.key):
        S = wavelet.support(letter)
        u = (fine_zyx[:, axis] - wavelet.offset(letter, m)) / scale
        k = np.floor(u)[:, None] - np.arange(S)[None, :]  # the S relevant indices (MATH.md §4)
        t = u[:, None] - k
        axis_vals.append(wavelet.prototype(letter, t))
        if derivative:
            axis_ders.append(wavelet.prototype(letter, t, d=1) / scale)
        inside = (k >= 0) & (k < band.shape[axis])
        axis_idx.append(np.where(inside, k, -1).astype(np.int64))
    padded = np.pad(coeffs, [(0, 1)] * 3 + [(0, 0)])  # index -1 reads the zero pad
    gathered = padded[axis_idx[0][:, :, None, None], axis_idx[1][:, None, :, None],
                      axis_idx[2][:, None, None, :]]  # (N, Sz, Sy, Sx, C)
    norm = scale ** -1.5
    if not derivative:
        return norm * np.einsum("nabcq,na,nb,nc->nq", gathered, *axis_vals)
    out = np.empty((n_pts, coeffs.shape[3], 3))
    for axis in range(3):
        factors = [axis_ders[a] if a == axis else axis_vals[a] for a in range(3)]
        out[:, :, axis] = norm * np.einsum("nabcq,na,nb,nc->nq", gathered, *factors)
    return out


def _synthesize(wavelet: SplineWavelet, bands, dense) -> tuple:
    """Real-line inverse transform: child index l = 2k + i + shift (shift = 1 - A or 1 - B).

    Follows from the offsets oA_m, oD_m of MATH.md §4 and the two-scale relations
    phi = sum p_i phi(2x - i), psi = sum q_i phi(2x - i), with filters h = p/sqrt2, g = q/sqrt2.
    """
    approx, start = dense[0], np.zeros(3, dtype=np.int64)
    filters = {"a": wavelet.p / np.sqrt(2.0), "d": wavelet.q / np.sqrt(2.0)}
    shifts = {"a": wavelet.synthesis_shift("a"), "d": wavelet.synthesis_shift("d")}
    by_level = {}
    for band, arr in zip(bands[1:], dense[1:]):
        by_level.setdefault(band.level, {})[band.key] = arr
    for m in sorted(by_level, reverse=True):
        details = by_level[m]
        shape = next(iter(details.values())).shape[:3]
        # put the running approximation and the details on one box per axis
        lo = np.minimum(start, 0)
        hi = np.maximum(start + approx.shape[:3], shape)
        parts = {"aaa": _place(approx, start - lo, hi - lo)}
        parts.update({k: _place(v, -lo, hi - lo) for k, v in details.items()})
        level_start = lo.copy()
        for axis in range(3):
            merged = {}
            for key, arr in parts.items():  # keys lose their leading letter per axis done
                up = upfirdn(filters[key[0]], arr, up=2, axis=axis)
                offset = 2 * level_start[axis] + shifts[key[0]]
                merged.setdefault(key[1:], []).append((offset, up))
            parts, new_start = {}, None
            for rest, pieces in merged.items():
                first = min(o for o, _ in pieces)
                last = max(o + p.shape[axis] for o, p in pieces)
                shape_out = list(pieces[0][1].shape)
                shape_out[axis] = last - first
                acc = np.zeros(shape_out)
                for o, p in pieces:
                    sl = [slice(None)] * acc.ndim
                    sl[axis] = slice(o - first, o - first + p.shape[axis])
                    acc[tuple(sl)] += p
                parts[rest] = acc
                new_start = first
            level_start[axis] = new_start
        approx, start = parts[""], level_start
    return approx, tuple(int(s) for s in start)


def _place(arr, offset, box) -> np.ndarray:
    """Zero-pad ``arr`` into a box of shape ``box`` at ``offset`` per axis."""
    pad = [(int(o), int(b - o - s)) for o, b, s in zip(offset, box, arr.shape[:3])] + [(0, 0)]
    return np.pad(arr, pad)
