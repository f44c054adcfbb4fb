"""Fine B-spline grids expanded on the device equal the host's real-line synthesis."""

import numpy as np
import pytest

import clwave
from clwave.device.context import ComputeContext
from clwave.raytrace.finegrid import fine_grids


def _on_box(arr, start, lo, shape):
    out = np.zeros(tuple(shape) + arr.shape[3:])
    o = np.asarray(start) - lo
    out[o[0]:o[0] + arr.shape[0], o[1]:o[1] + arr.shape[1], o[2]:o[2] + arr.shape[2]] = arr
    return out


@pytest.mark.parametrize("wavelet", ["haar", "linear", "quadratic", "cubic"])
@pytest.mark.parametrize("levels", [0, 2])
def test_device_expansion_equals_host_synthesis(wavelet, levels):
    rng = np.random.default_rng(levels)
    vol = clwave.Volume(rng.random((13, 10, 11, 2)).astype(np.float32), spacing=(1.0, 2.0, 0.5))
    wv = clwave.WaveletVolume.from_volume(vol, wavelet=wavelet, levels=levels).threshold(keep=0.3)
    (grid,), _ = fine_grids(wv, ComputeContext.get(), pad=3)
    ref, ref_start = wv.fine_coefficients(0)
    got = grid.data.get()
    assert grid.order == wv.groups[0].wavelet.order and np.all(got[..., 2:] == 0)
    lo = np.minimum(ref_start, grid.start)
    hi = np.maximum(np.add(ref_start, ref.shape[:3]), np.add(grid.start, got.shape[:3]))
    diff = _on_box(got[..., :2], grid.start, lo, hi - lo) - _on_box(ref, ref_start, lo, hi - lo)
    assert np.max(np.abs(diff)) <= 1e-6 * np.abs(ref).max()
    # the padding is zero: three points beyond every side
    assert not np.any(got[:3]) and not np.any(got[-3:]) and not np.any(got[:, :3]) and not np.any(got[..., -3:, :])


def test_channels_go_to_their_slots():
    rng = np.random.default_rng(0)
    data = rng.random((8, 8, 8, 4)).astype(np.float32)
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), wavelet=["cubic", "cubic", "cubic", "haar"], levels=1)
    grids, _ = fine_grids(wv, ComputeContext.get())
    by_order = {g.order: g.data.get() for g in grids}
    assert set(by_order) == {4, 1}
    assert not np.any(by_order[4][..., 3]) and not np.any(by_order[1][..., :3]) and np.any(by_order[1][..., 3])
