"""The wavelet transform of a volume and back (docs/model.md §1-4): the band layout of a
decomposition, analysis with PyWavelets (zero extension), the real-line synthesis, and the
continuous model evaluated from the closed-form bases."""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from itertools import product

import numpy as np
import pywt
from scipy.linalg import solve_banded
from scipy.ndimage import correlate1d

from ..errors import InputError
from ..io.progress import progress
from ..threads import thread_map
from .bspline import SplineWavelet


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
        """``level * 8 + code``: the band in the splatting kernels' tables (a coefficient's ``RankedTable.band``)."""
        return self.level * 8 + self.code


def band_layout(wavelet: SplineWavelet, shape, levels) -> list:
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
            return
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="Level value of .* is too high")
            coeffs = pywt.wavedecn(data, wavelet.pywt, mode="zero", level=levels)
        parts = [coeffs[0]] + [detail[key] for detail in coeffs[1:] for key in KEYS[1:]]
        for band, part in zip(bands, parts):
            values[slot, band.start:band.start + band.size] = part.ravel()
        check_coefficients(values[slot])

    jobs = list(enumerate(channels))
    with progress(total=len(jobs), desc=f"{wavelet.name} transform", enabled=progress_bar) as bar:
        thread_map(lambda job: (one(job), bar.update(1)), jobs)
    return bands, values


def check_coefficients(values, frame=None):
    """Refuse coefficients that overflowed float32 (voxels near its largest value, 3.4e38): nothing
    non-finite may reach a kernel or an image.  With ``frame`` (shape, spacing), the values are the voxels' own
    B-spline coefficients (the model at 0 levels, or the volume before its transform): as the B-splines sum to 1,
    the model is at most their largest value, so no line integral through the volume passes it times the volume's
    diagonal, which must be finite in float32 too (a splat or ray-traced image would be inf)."""
    if not np.all(np.isfinite(values)):
        raise InputError("the wavelet transform of this volume overflows float32 (its values come too close to "
                         "3.4e38); rescale the volume first, e.g. to [0, 1]")
    if frame is not None and np.size(values):
        diagonal = float(np.linalg.norm(np.multiply(frame[0], frame[1])))
        largest = float(np.abs(values).max())
        if not largest * diagonal < float(np.finfo(np.float32).max):
            raise InputError(f"the line integrals of this volume overflow float32 (its largest value {largest:.3g} "
                             f"times its diagonal {diagonal:.3g} passes 3.4e38); rescale its values first, e.g. "
                             f"to [0, 1], or its spacing")


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


def band_sum(wavelet, band, coeffs, fine_zyx, derivative) -> np.ndarray:
    """Sum of one band's basis functions at fine points (N, 3), (N, C) or (N, C, 3) in (z, y, x)."""
    m, scale = band.level, 2.0 ** band.level
    n_pts = len(fine_zyx)
    axis_vals, axis_ders, axis_idx = [], [], []
    for axis, letter in enumerate(band.key):
        S = wavelet.support(letter)
        u = (fine_zyx[:, axis] - wavelet.offset(letter, m)) / scale
        k = np.floor(u)[:, None] - np.arange(S)[None, :]  # the S relevant indices (docs/model.md §4)
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


def synthesize(wavelet: SplineWavelet, bands, dense) -> tuple:
    """Real-line inverse transform: child index l = 2k + i + shift (shift = 1 - A or 1 - B).

    Follows from the offsets oA_m, oD_m of docs/model.md §4 and the two-scale relations
    phi = sum p_i phi(2x - i), psi = sum q_i phi(2x - i), with filters h = p/sqrt2, g = q/sqrt2.
    """
    # imported here: scipy.signal brings scipy.stats, a second of every start-up, and only reconstruction needs it
    from scipy.signal import upfirdn

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
