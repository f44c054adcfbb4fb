"""The wavelet transform of a volume and back (docs/model.md §1-4): the band layout of a
decomposition, analysis with PyWavelets (zero extension), the real-line synthesis, and the
continuous model evaluated from the closed-form bases."""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from itertools import product

import numpy as np
import pywt
from scipy.linalg import solve_banded
from scipy.ndimage import correlate1d

from ..errors import ClwaveWarning, InputError, warn_outside
from ..io.progress import progress
from ..threads import thread_map
from .bspline import SplineWavelet, max_levels, wavelet_for


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

    @property
    def id(self) -> int:
        """``level * 8 + code``: the band in the splatting kernels' tables (a coefficient's ``RankedTable.band``);
        :func:`band_level`, :func:`band_code` and :func:`band_key` read it back."""
        return self.level * 8 + self.code


def band_level(band_id):
    """The level m of a :attr:`Band.id` (an int, or an integer array of them)."""
    return band_id // 8


def band_code(band_id):
    """The subband code of a :attr:`Band.id` (an int, or an integer array of them): 0 for the approximation."""
    return band_id % 8


def band_key(band_id) -> str:
    """The (z, y, x) letters of a :attr:`Band.id`'s subband (the inverse of :attr:`Band.code`), e.g. "aad"."""
    return "".join("ad"[band_code(band_id) >> (2 - a) & 1] for a in range(3))


def band_layout(wavelet: SplineWavelet, shape, levels) -> list:
    """Bands of a pywt mode='zero' decomposition (:func:`wavedecn`), coarsest approximation first."""
    sizes = [tuple(shape)]  # every band of level m has the approximation's shape after m steps
    for _ in range(levels):
        sizes.append(tuple(pywt.dwt_coeff_len(n, wavelet.pywt.dec_len, "zero") for n in sizes[-1]))
    layout = [(levels, "aaa", sizes[levels])] + [(m, key, sizes[m]) for m in range(levels, 0, -1) for key in KEYS[1:]]
    bands, start = [], 0
    for m, key, shp in layout:
        bands.append(Band(m, key, shp, start))
        start += int(np.prod(shp))
    return bands


def prefilter(data: np.ndarray, wavelet: SplineWavelet) -> np.ndarray:
    """B-spline coefficients whose model interpolates ``data`` at voxel centres (zero extension)."""
    w = sampling_kernel(wavelet)
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


def sampling_kernel(wavelet: SplineWavelet) -> np.ndarray:
    """Weights w_s with f(i + j/2) = sum_s w_s c_{i-s} (docs/model.md §1)."""
    j = wavelet.order
    half = (j - 1) // 2
    s = np.arange(-half, half + 1)
    return wavelet.phi(s + j / 2.0)


def apply_sampling_filter(coeffs, start, wavelet):
    w = sampling_kernel(wavelet)
    half = len(w) // 2
    if half == 0:
        return coeffs, start
    padded = np.pad(coeffs, [(half, half)] * 3 + [(0, 0)])
    for axis in range(3):
        padded = correlate1d(padded, w, axis=axis, mode="constant")
    return padded, tuple(s - half for s in start)


def crop_to_grid(coeffs, start, shape) -> np.ndarray:
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


def wavedecn(data, wavelet: SplineWavelet, levels, step=lambda: None) -> list:
    """``pywt.wavedecn(data, wavelet.pywt, mode="zero", level=levels)`` without its check of the level: a level past
    pywt's largest for the filter's length is ours to ask for (docs/model.md §2), and silencing pywt's warning with
    ``warnings.catch_warnings`` is not thread-safe (:func:`decompose` runs a thread a channel).  An axis at a time, as
    ``pywt.dwtn`` does, calling ``step`` after each (a bar's update)."""
    details, approximation = [], data
    for _ in range(levels):
        detail = {"": approximation}
        for axis in range(3):
            detail = {key + letter: part for key, halves in detail.items()
                      for letter, part in zip("ad", pywt.dwt(halves, wavelet.pywt, mode="zero", axis=axis))}
            step()
        approximation = detail.pop("aaa")
        details.append(detail)
    return [approximation] + details[::-1]


def decompose(volume, wavelet, channels, levels, interpolate, progress_bar) -> tuple:
    """``(bands, values)``: the real-line transform of the volume's ``channels`` (one thread each),
    values (channels, positions) float32 in the band layout's order (docs/model.md §2-3)."""
    bands = band_layout(wavelet, volume.shape, levels)
    total = bands[-1].start + bands[-1].size
    values = np.empty((len(channels), total), dtype=np.float32)

    def one(slot_channel):
        slot, channel = slot_channel
        data = volume.channel(channel)
        if interpolate:
            data = prefilter(data, wavelet).astype(np.float32)
        check_coefficients(data, (volume.shape, volume.spacing))  # the voxels' B-spline coefficients
        if levels == 0:
            values[slot] = data.ravel()
            bar.update(1)
            return
        coeffs = wavedecn(data, wavelet, levels, lambda: bar.update(1))
        parts = [coeffs[0]] + [detail[key] for detail in coeffs[1:] for key in KEYS[1:]]
        for band, part in zip(bands, parts):
            values[slot, band.start:band.start + band.size] = part.ravel()
        check_coefficients(values[slot])

    # the bar counts each channel's passes along an axis of a level (a channel at 0 levels): a scalar's moves too
    with progress(total=len(channels) * max(3 * levels, 1), desc=f"{wavelet.name} transform",
                  enabled=progress_bar) as bar:
        thread_map(one, list(enumerate(channels)))
    return bands, values


#: the largest sum of quadrature weights times samples the ray tracer forms before it scales by the step
#: (cl/raytrace/quadrature.h: Simpson's pair, 1 + 4 + 2 + 4 + 1)
QUADRATURE_WEIGHTS = 12.0

#: no coefficient may reach it (1.8e19, the root of float32's largest): their squares are summed as energies
LARGEST_COEFFICIENT = float(np.sqrt(np.finfo(np.float32).max))


def check_coefficients(values, frame=None):
    """Refuse coefficients that overflowed float32 (voxels near its largest value, 3.4e38), or whose squares would:
    nothing non-finite may reach a kernel or an image, nor the energies (sums of squares) that threshold a model,
    estimate a view's error and measure a compressed file's, so no coefficient may pass 1.8e19, the root of 3.4e38.
    With ``frame`` (shape, spacing), the values are the voxels' own B-spline coefficients (the model at 0 levels,
    or the volume before its transform): as the B-splines sum to 1, the model is at most their largest value, so no
    line integral through the volume passes it times the volume's diagonal, nor the ray tracer's quadrature sums of
    samples on the way :data:`QUADRATURE_WEIGHTS` times a sample; the larger of the two must stay below 1.8e19 too,
    so that an image's squares (its energy, a progressive frame's error) are finite in float32."""
    if not np.all(np.isfinite(values)):
        raise InputError("the wavelet transform of this volume overflows float32 (its values come too close to "
                         "3.4e38); rescale the volume first, e.g. to [0, 1]")
    if not np.size(values):
        return
    root, largest = LARGEST_COEFFICIENT, float(np.abs(values).max())
    if frame is None and not largest < root:
        raise InputError(f"the energies of this volume overflow float32 (its largest wavelet coefficient "
                         f"{largest:.3g} squared passes 3.4e38); rescale its values first, e.g. to [0, 1]")
    if frame is not None:
        diagonal = float(np.linalg.norm(np.multiply(frame[0], frame[1])))
        if not largest * max(diagonal, QUADRATURE_WEIGHTS) < root:
            times = f"its diagonal {diagonal:.3g}" if diagonal >= QUADRATURE_WEIGHTS else \
                f"the ray tracer's quadrature weights {QUADRATURE_WEIGHTS:g} (its diagonal is {diagonal:.3g})"
            raise InputError(f"the line integrals of this volume overflow float32 once squared (its largest value "
                             f"{largest:.3g} times {times} passes 1.8e19, the root of 3.4e38: their squares, summed "
                             f"as energies, would be inf); rescale its values first, e.g. to [0, 1], or its spacing")


def reconstruct_channel(group, dense, slot, shape, levels) -> np.ndarray:
    """One channel back on the voxel grid through PyWavelets."""
    if levels == 0:
        return dense[0][..., slot]
    coeffs = [dense[0][..., slot]]
    for i in range(levels):
        coeffs.append({b.key: arr[..., slot] for b, arr in zip(group.bands[1 + 7 * i:8 + 7 * i],
                                                             dense[1 + 7 * i:8 + 7 * i])})
    out = pywt.waverecn(coeffs, group.wavelet.pywt, mode="zero")
    return out[tuple(slice(0, n) for n in shape)]


#: bytes of basis reads one band_sum pass gathers at once: the points go through in chunks of this size
GATHER_BYTES = 32 << 20


def band_sum(wavelet, band, coeffs, fine_zyx, derivative) -> np.ndarray:
    """Sum of one band's basis functions at fine points (N, 3), (N, C) or (N, C, 3) in (z, y, x).

    ``coeffs``: the band's (nz, ny, nx, C) array, or an object of that ``shape`` whose ``[iz, iy, ix]`` (broadcast
    index arrays) reads it (``evaluation.SparseBand``).  An index beyond the band reads nothing (its weight is
    zero).  The points go through in chunks of at most :data:`GATHER_BYTES` of reads."""
    C = coeffs.shape[3]
    out = np.empty((len(fine_zyx), C, 3) if derivative else (len(fine_zyx), C))
    chunk = max(1, GATHER_BYTES // (band_reads(wavelet, band) * C * 8))
    for lo in range(0, len(fine_zyx), chunk):
        out[lo:lo + chunk] = _band_sum(wavelet, band, coeffs, fine_zyx[lo:lo + chunk], derivative)
    return out


def band_reads(wavelet, band) -> int:
    """The coefficients of ``band`` whose basis functions reach a point: the product of the supports along the
    axes (what :func:`band_sum` reads a point)."""
    return int(np.prod([wavelet.support(letter) for letter in band.key]))


def _band_sum(wavelet, band, coeffs, fine_zyx, derivative) -> np.ndarray:
    m, scale = band.level, 2.0 ** band.level
    axis_vals, axis_ders, axis_idx = [], [], []
    for axis, letter in enumerate(band.key):
        S = wavelet.support(letter)
        u = (fine_zyx[:, axis] - wavelet.offset(letter, m)) / scale
        k = np.floor(u)[:, None] - np.arange(S)[None, :]  # the S relevant indices (docs/model.md §4)
        t = u[:, None] - k
        inside = (k >= 0) & (k < band.shape[axis])
        axis_vals.append(wavelet.prototype(letter, t) * inside)
        if derivative:
            axis_ders.append(wavelet.prototype(letter, t, d=1) / scale * inside)
        axis_idx.append(np.clip(k, 0, band.shape[axis] - 1).astype(np.int64))
    gathered = coeffs[axis_idx[0][:, :, None, None], axis_idx[1][:, None, :, None],
                      axis_idx[2][:, None, None, :]]  # (N, Sz, Sy, Sx, C)
    norm = scale ** -1.5
    if not derivative:
        return norm * np.einsum("nabcq,na,nb,nc->nq", gathered, *axis_vals)
    out = np.empty((len(fine_zyx), coeffs.shape[3], 3))
    for axis in range(3):
        factors = [axis_ders[a] if a == axis else axis_vals[a] for a in range(3)]
        out[:, :, axis] = norm * np.einsum("nabcq,na,nb,nc->nq", gathered, *factors)
    return out


def synthesize(wavelet: SplineWavelet, bands, coefficients, region=None) -> tuple:
    """Real-line inverse transform down to the finest level the bands reach: ``(coeffs (Z, Y, X, C) float64,
    start)``, ``coeffs[i, j, k]`` the coefficient of index ``start + (i, j, k)`` on that level's lattice.

    ``coefficients``: the bands' dense arrays, or a function ``(band number, lo, hi)`` giving that band's
    coefficients on the index box [lo, hi) per axis, zeros beyond the band (``evaluation.group_box``).  ``region``:
    ``(lo, hi)``, the output indices wanted (default: all the model reaches); each level reads and filters only
    its coefficients that reach them (:func:`synthesis_boxes`), so a region costs about its own size.

    A parent k of part 'a' or 'd' goes to the children ``l = 2k + i + shift``, i over the filter's taps, shift
    = 1 - A or 1 - B: from the offsets oA_m, oD_m of docs/model.md §4 and the two-scale relations
    phi = sum p_i phi(2x - i), psi = sum q_i phi(2x - i), with filters h = p/sqrt2, g = q/sqrt2.
    """
    box = coefficients if callable(coefficients) else partial(_dense_box, coefficients)
    filters = {"a": wavelet.p / np.sqrt(2.0), "d": wavelet.q / np.sqrt(2.0)}
    boxes = synthesis_boxes(wavelet, bands, region)
    approx = box(0, *boxes[0])
    for m, (lo, hi), (child_lo, child_hi) in zip(_detail_levels(bands), boxes, boxes[1:]):
        parts = {"aaa": approx}
        parts.update({b.key: box(i, lo, hi) for i, b in enumerate(bands) if i and b.level == m})
        for axis in range(3):  # keys lose their leading letter per axis done
            merged = {}
            for key in list(parts):  # each part freed once filtered (the peak: docs/model.md §4)
                part = parts.pop(key)
                shape = list(part.shape)
                shape[axis] = child_hi[axis] - child_lo[axis]
                acc = merged.setdefault(key[1:], np.zeros(shape))
                first = 2 * lo[axis] + wavelet.synthesis_shift(key[0]) - child_lo[axis]  # part[0]'s children in acc
                _upsample_into(acc, part, filters[key[0]], first, axis)
            parts = merged
        approx = parts[""]
    return approx, tuple(int(s) for s in boxes[-1][0])


def _upsample_into(acc, part, taps, first, axis):
    """Add each parent k of ``part`` (along ``axis``) times tap i to ``acc`` at ``first + 2k + i``, the children
    inside ``acc`` alone: a box a few indices thick along an axis computes no more children there than it keeps
    (scipy.signal.upfirdn makes all 2n + F - 2 of them, several times as many on a slice's box)."""
    n, size = part.shape[axis], acc.shape[axis]
    for i, tap in enumerate(taps):
        k0 = max(0, -((first + i) // 2))  # the parents whose child first + 2k + i lies in [0, size)
        k1 = min(n, (size - 1 - first - i) // 2 + 1)
        if k1 > k0:
            dst, src = [slice(None)] * acc.ndim, [slice(None)] * acc.ndim
            dst[axis] = slice(first + i + 2 * k0, first + i + 2 * (k1 - 1) + 1, 2)
            src[axis] = slice(k0, k1)
            acc[tuple(dst)] += tap * part[tuple(src)]


def synthesis_boxes(wavelet: SplineWavelet, bands, region=None) -> list:
    """The index boxes ``(lo, hi)`` (int64 (3,) each, half-open) :func:`synthesize` works on, from the approximation
    band's level to the finest: without ``region``, all the model reaches (every index a kept coefficient's
    children touch); with it, that reach cut to ``region`` at the finest level and, above, to the parents of
    the box below."""
    spans = [(wavelet.synthesis_shift(letter), len(wavelet.p if letter == "a" else wavelet.q)) for letter in "ad"]
    reach = [(np.zeros(3, np.int64), np.array(bands[0].shape, np.int64))]
    for m in _detail_levels(bands):  # parents [lo, hi) reach the children [2 lo + s, 2 (hi - 1) + s + F)
        lo = np.minimum(reach[-1][0], 0)
        hi = np.maximum(reach[-1][1], next(b.shape for b in bands[1:] if b.level == m))
        reach[-1] = (lo, hi)
        reach.append((2 * lo + min(s for s, _ in spans), 2 * (hi - 1) + max(s + f for s, f in spans)))
    if region is None:
        return reach
    boxes = [_cut(reach[-1], np.asarray(region[0], np.int64), np.asarray(region[1], np.int64))]
    for level_reach in reach[-2::-1]:  # the parents of children [c_lo, c_hi): 2k + i + s in it for a tap i < F
        c_lo, c_hi = boxes[0]
        boxes.insert(0, _cut(level_reach, np.min([-((s + f - 1 - c_lo) // 2) for s, f in spans], axis=0),
                             np.max([(c_hi - 1 - s) // 2 + 1 for s, _ in spans], axis=0)))
    return boxes


def _cut(box, lo, hi) -> tuple:
    """``box`` cut to [lo, hi) (an empty box where they miss)."""
    lo = np.maximum(box[0], lo)
    return lo, np.maximum(np.minimum(box[1], hi), lo)


def _detail_levels(bands) -> list:
    """The levels of the detail bands, coarsest first."""
    return sorted({b.level for b in bands[1:]}, reverse=True)


def _dense_box(dense, number, lo, hi) -> np.ndarray:
    """Band ``number`` of the dense arrays on the index box [lo, hi), zeros beyond it."""
    return crop_to_grid(dense[number], tuple(-np.asarray(lo)), tuple(np.asarray(hi) - lo))


#: decomposition levels of a model made without ``levels`` (fewer where the volume's shortest axis allows fewer)
DEFAULT_LEVELS = 3


def check_decomposition(shape, channels, wavelet, levels) -> tuple:
    """``(wavelet of each channel, levels)``, checked for a volume of ``shape`` and ``channels``
    before any work (:meth:`WaveletVolume.from_volume` takes the same arguments); ``levels`` None is the
    default, lowered with a :class:`ClwaveWarning` where the shape allows fewer (:func:`default_levels`)."""
    if levels is None:
        levels, note = default_levels(shape, thresholded=False)
        if note:
            warn_outside(ClwaveWarning(note))
    return _channel_wavelets(wavelet, channels), _check_levels(levels, shape)


def _channel_wavelets(wavelet, channels) -> list:
    if isinstance(wavelet, (list, tuple)):
        if len(wavelet) != channels:
            raise InputError(f"{len(wavelet)} wavelets given for {channels} channel(s); give one, "
                             "or one per channel")
        return [wavelet_for(w) for w in wavelet]
    return [wavelet_for(wavelet)] * channels


def default_levels(shape, levels=DEFAULT_LEVELS, thresholded=True) -> tuple:
    """``(levels, note)`` for a volume of ``shape`` (z, y, x[, c]) given no levels: ``levels``, or as many as its
    shortest axis allows (:func:`max_levels`: every level halves every axis), with a one-line note in the
    command line's words when the axis caps them (None otherwise).  At 0 levels the model is the voxels
    themselves, so a ``thresholded`` one (``--keep`` below 1) drops voxels: the note says so, and what helps."""
    spatial = tuple(shape[:3])
    top = max(0, max_levels(spatial))  # an axis of 1 voxel (max_levels -1) allows no level either
    if top >= levels:
        return levels, None
    axis = int(np.argmin(spatial))
    note = (f"{top} decomposition level{'s' if top != 1 else ''} instead of the default {levels}: the "
            f"{'zyx'[axis]} axis of {spatial[axis]} voxels allows no more (every level halves every axis)")
    if top == 0 and thresholded:
        note += ("; with no levels the model is the voxels themselves, and --keep drops voxels: give --keep 1, or "
                 "a volume at least 4 voxels thick for 1 level")
    return top, note


def _check_levels(levels, shape) -> int:
    top = max_levels(shape)
    if isinstance(levels, bool) or not isinstance(levels, (int, np.integer)) or not 0 <= levels <= top:
        why = f"is not possible for shape {shape}: use an integer from 0 to {top} (floor(log2(shortest axis)) - 1)"
        raise InputError(f"levels={levels!r} {why}", cli=f"--levels {levels} {why}")
    return int(levels)
