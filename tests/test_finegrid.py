"""Fine B-spline grids expanded on the device equal the host's real-line synthesis, zero on empty voxels."""

import numpy as np
import pytest

import clwave
from clwave.device.context import ComputeContext
from clwave.raytrace.finegrid import content_weights, fine_grids


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
    ref = ref * content_weights(wv.content_mask, ref_start, ref.shape[:3])[..., None]  # zero beyond the voxels
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


def test_fine_coefficients_of_empty_voxels_are_zero():
    """A thresholded model rings beyond the non-zero voxels; its B-spline field does not (the full model's
    fine coefficients there are zero), and keeps the thresholded coefficients on non-zero voxels."""
    data = np.zeros((16, 14, 12, 4), np.float32)
    data[4:11, 3:9, 5:10] = np.random.default_rng(4).random((7, 6, 5, 4))
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), wavelet="cubic", levels=2).threshold(keep=0.1)
    (grid,), _ = fine_grids(wv, ComputeContext.get())
    got, start = grid.data.get(), np.array(grid.start)
    ref, ref_start = wv.fine_coefficients(0)
    assert np.abs(ref[..., 3]).max() > 0 and start[0] < 0  # the synthesis reaches beyond the voxel box
    inside = tuple(slice(-s, -s + n) for s, n in zip(start, data.shape[:3]))
    outside = np.ones(got.shape[:3], bool)
    outside[inside] = data[..., 0] == 0
    assert not np.any(got[outside]) and np.any(got[~outside])
    at = tuple(slice(-s, -s + n) for s, n in zip(ref_start, data.shape[:3]))
    np.testing.assert_allclose(got[inside][data[..., 0] != 0], ref[at][data[..., 0] != 0], rtol=0, atol=1e-6)
