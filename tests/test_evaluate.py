"""WaveletVolume.evaluate / gradient: the fine path (a region's synthesis, model/evaluation.py) against the band sum,
the cost rule's choice, the coefficients kept, and the region synthesis against the whole one."""

import numpy as np
import pytest

from clwave.errors import InputError
from clwave.model import evaluation
from clwave.model.bspline import bspline
from clwave.model.geometry import fine_to_world, world_to_fine
from clwave.model.transform import crop_to_grid, synthesize
from clwave.model.volume import Volume
from clwave.model.wavelet import WaveletVolume

SHAPE = (16, 19, 17)  # (z, y, x): odd and unequal, 3 levels allowed
SPACING = (2.0, 1.0, 0.5)
# every order the package has, one group each, and one group of three channels
MIXES = (("haar", "linear", "quadratic", "cubic"), ("quintic", "quintic", "quintic", "linear"))


def volume(rng, channels=4) -> Volume:
    """Random channels, zero on a third of the grid (the content mask then clamps something)."""
    data = rng.random(SHAPE + (channels,)).astype(np.float32)
    data[:, :7] = 0
    return Volume(data if channels > 1 else data[..., 0], spacing=SPACING, origin=(1.0, -2.0, 0.5))


def probe_points(wv, rng, n=150) -> np.ndarray:
    """World points inside the grid, on knots (integer fine coordinates of every order), just outside it and far
    beyond the model's reach."""
    half = np.array(wv.shape[::-1]) * np.array(wv.spacing[::-1]) / 2
    origin = np.array(wv.origin)
    inside = origin + rng.uniform(-1, 1, (n, 3)) * half
    # the knots are the fine integers: of the even orders through the map of order 0, of the odd through order 1's
    knots = [fine_to_world(rng.integers(-3, np.array(wv.shape) + 6, (n // 6, 3)).astype(float), parity, wv.shape,
                           wv.spacing, wv.origin) for parity in (0, 1)]
    near = origin + rng.uniform(-1, 1, (n // 3, 3)) * (half + 6 * np.array(wv.spacing[::-1]))
    far = origin + np.array([[1e4, 0, 0], [0, -3e3, 0], [0, 0, 5e3], [1e19, 0, 0], [0, -1e300, 0]])
    return np.concatenate([inside, *knots, near, far])


def close(a, b):
    """Equal to float64 rounding: 1e-12 of the largest value."""
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * max(1.0, np.max(np.abs(b))))


@pytest.mark.parametrize("mix", MIXES)
@pytest.mark.parametrize("levels", [1, 2, 3])
def test_fine_path_equals_band_sum(mix, levels, rng):
    wv = WaveletVolume.from_volume(volume(rng), list(mix), levels=levels).threshold(keep=0.15)
    assert len(wv.groups) == (4 if mix == MIXES[0] else 2) and wv.content_mask is not None
    pts = probe_points(wv, rng)
    bands, grads = wv.evaluate(pts, "bands"), wv.gradient(pts, "bands")
    assert np.max(np.abs(bands)) > 0.1 and np.max(np.abs(grads[:, 1:])) > 0.01  # the probe reads something
    close(wv.evaluate(pts, "fine"), bands)
    close(wv.gradient(pts, "fine"), grads)
    close(wv.evaluate(pts), bands)
    assert np.all(bands[-3:] == 0) and np.all(wv.evaluate(pts[-3:], "fine") == 0)  # beyond the reach


@pytest.mark.parametrize("method", evaluation.METHODS)
@pytest.mark.parametrize("family, order", [("haar", 1), ("linear", 2), ("quadratic", 3), ("cubic", 4),
                                           ("quintic", 6)])
def test_every_coefficient_is_the_fine_spline_of_the_voxels(method, family, order, rng):
    """Closed form: with every coefficient kept the model is sum_i v_i N_j(x - i) of the voxels (docs/model.md §4)."""
    data = rng.random(SHAPE).astype(np.float32)
    wv = WaveletVolume.from_volume(Volume(data, spacing=SPACING), family, levels=2)
    pts = rng.uniform(-1, 1, (200, 3)) * np.array([6.0, 12.0, 20.0])
    fine = world_to_fine(pts, order, SHAPE, SPACING, (0, 0, 0))
    w = [bspline(order, fine[:, a, None] - np.arange(n)[None, :]) for a, n in enumerate(SHAPE)]
    assert np.max(np.abs(wv.evaluate(pts, method)[:, 0] - np.einsum("ijk,ni,nj,nk->n", data, *w))) < 1e-5


def test_content_mask_does_not_clamp(rng):
    """evaluate is the model of every kept coefficient: the content mask (zero voxels) changes nothing."""
    wv = WaveletVolume.from_volume(volume(rng, channels=1), "cubic", levels=2).threshold(keep=0.05)
    empty = wv.content_mask.box((0, 0, 0), wv.shape) == 0
    assert empty.any()
    pts = fine_to_world(np.argwhere(empty) + 2.0, 4, wv.shape, wv.spacing, wv.origin)  # empty voxels' centres
    for method in evaluation.METHODS:
        values = wv.evaluate(pts, method)[:, 0]
        assert np.max(np.abs(values)) > 1e-3  # the thresholded model rings into empty voxels: not clamped
        close(values, wv.unmasked().evaluate(pts, method)[:, 0])


def test_region_synthesis_is_the_whole_synthesis_cut(rng):
    for family in ("haar", "linear", "quadratic", "cubic", "quintic"):
        wv = WaveletVolume.from_volume(volume(rng, channels=2), family, levels=2).threshold(keep=0.2)
        g = wv.groups[0]
        whole, start = synthesize(g.wavelet, g.bands, g.dense_bands())
        cases = [(np.add(start, (3, 5, 2)), np.add(start, (7, 14, 8))),  # inside the reach
                 (np.array([-70, -70, -70]), np.array([-40, -68, 430])),  # partly beyond: cut to it (haar: empty)
                 (np.array(start), np.add(start, whole.shape[:3]))]  # the whole reach
        for lo, hi in cases:
            part, at = synthesize(g.wavelet, g.bands, lambda i, a, b: evaluation.group_box(g, i, a, b), (lo, hi))
            assert np.array_equal(at, np.maximum(lo, start))
            end = np.maximum(np.minimum(hi, np.add(start, whole.shape[:3])), at)  # empty where the box misses it
            assert np.array_equal(np.add(at, part.shape[:3]), end)
            assert np.array_equal(part, crop_to_grid(whole, tuple(np.subtract(start, at)), part.shape[:3]))


def test_cost_rule_and_the_coefficients_kept(rng, monkeypatch):
    # details kept: the band sum reads 1,443 a point here (an approximation alone reads 64, as the fine path does,
    # and never pays), so the box pays from 170 points
    wv = WaveletVolume.from_volume(volume(rng), "cubic", levels=2).threshold(keep=0.4)
    pts = probe_points(wv, rng, 3000)[:-3]
    wv.evaluate(pts[:10])
    assert wv._fine == {}  # ten points: the band sum, nothing made
    expected = wv.evaluate(pts, "bands")
    close(wv.evaluate(pts), expected)
    coeffs, start = wv._fine[0]  # many points: their region, kept
    assert coeffs.dtype == np.float64 and coeffs.nbytes <= evaluation.REGION_BYTES
    close(wv.evaluate(pts[:10]), expected[:10])  # then ten points read it
    assert wv._fine[0][0] is coeffs
    assert wv.unmasked()._fine[0][0] is coeffs  # a copy without the mask shares it: evaluate ignores masks
    thresholded = wv.threshold(keep=0.02)  # a new model: nothing kept from this one's
    assert thresholded._fine == {}
    close(thresholded.evaluate(pts, "fine"), thresholded.evaluate(pts, "bands"))
    wv.release()
    assert wv._fine == {}
    # a region over the byte bound goes in slabs along z, each at most that
    monkeypatch.setattr(evaluation, "REGION_BYTES", 1 << 20)
    close(wv.gradient(pts, "fine"), wv.gradient(pts, "bands"))
    kept = wv._fine[0][0]
    assert kept.nbytes <= 1 << 20 and kept.shape[0] <= 2 * evaluation.REGION_STEP  # the last slab's
    # a slab (at least 8 z layers) still over the bound: "auto" sums the bands there, keeping nothing over it
    wv.release()
    monkeypatch.setattr(evaluation, "REGION_BYTES", 1 << 12)
    close(wv.evaluate(pts), expected)
    assert all(c.nbytes <= 1 << 12 for c, _ in wv._fine.values())


def test_bad_method_and_no_points(rng):
    wv = WaveletVolume.from_volume(volume(rng, channels=1), "linear", levels=1)
    with pytest.raises(InputError, match="method='exact' is not one of 'auto', 'bands', 'fine'"):
        wv.evaluate(np.zeros((2, 3)), "exact")
    assert wv.evaluate(np.zeros((0, 3)), "fine").shape == (0, 1)
    assert wv.gradient(np.zeros((0, 3))).shape == (0, 1, 3)
