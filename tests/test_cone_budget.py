"""The refined bands' prediction (clwave/splat/cone_budget.py, docs/splatting.md §8 "Refined bands"): its inputs
against brute force and exact line integrals, its sums of the levels' errors, its choice, and its prediction against
the exact perspective line integrals of the same model (``reference.exact_xray``) where it refines and where not."""

from types import SimpleNamespace

import numpy as np
import pytest

import clwave
from clwave.io.phantoms import phantom
from clwave.model.bspline import SplineWavelet
from clwave.model.geometry import fine_to_world, support_centres, view_frame
from clwave.splat import cone_budget, perspective
from clwave.splat.perspective import sheared_footprints
from clwave.splat.reference import exact_xray

BOUND = 1e-2  # of the image maximum (issue #33)


def _exact_fine(wv, camera):
    """The exact image of the model's fine coefficients, those beyond the voxel grid too."""
    coeffs, start = wv.fine_coefficients(0)
    d, shape, grid = np.array(wv.spacing), np.array(coeffs.shape[:3]), np.array(wv.shape)
    origin = np.array(wv.origin) + (d * ((shape - grid) / 2.0 + np.asarray(start)))[::-1]
    return exact_xray(coeffs, wv.groups[0].wavelet.order, wv.spacing, origin, camera.view(wv))


def _inputs(wv, camera):
    """The arguments ConeTables gives :func:`cone_budget.refined_bands` for ``camera``."""
    seen = {}

    def grab(*args):
        seen["args"] = args
        raise KeyboardInterrupt  # stop before any footprint is made

    original, perspective.refined_bands = perspective.refined_bands, grab
    try:
        clwave.SplatRenderer(wv).begin(camera)
    except KeyboardInterrupt:
        pass
    finally:
        perspective.refined_bands = original
    return seen["args"]


def test_projections_hold_each_bands_coefficients_at_their_centres():
    # against brute force: each kept coefficient's support centre projected along the view, one at a time, and its
    # value (and square) added into the cell of a grid of the pitch from the least cell of every band
    vol = clwave.Volume(np.random.default_rng(3).random((10, 12, 14)).astype(np.float32), spacing=(1.5, 1.0, 0.75))
    wv = clwave.WaveletVolume.from_volume(vol, levels=2).threshold(keep=0.3)
    view = clwave.Camera(35, 25, 16, perspective=True, distance=60).view(wv)
    g, pitch = wv.groups[0], 0.6
    sums = cone_budget.projections(wv, 0, view, pitch)
    points = {}
    for b, part in zip(g.bands, g.band_slices()):
        for position, value in zip(g.all_positions()[part], g.values[0, part]):
            index = np.unravel_index(position - b.start, b.shape)
            centre = fine_to_world(support_centres(g.wavelet, b.key, b.level, index), 4, wv.shape, wv.spacing,
                                   wv.origin)
            offset = centre - np.asarray(wv.origin)
            points.setdefault((b.level, b.key), []).append((round(offset @ view.v / pitch),
                                                            round(offset @ view.u / pitch), float(value)))
    lo = np.min([(i, j) for band in points.values() for i, j, _ in band], axis=0)
    for band, kept in points.items():
        expected = np.zeros((2,) + sums[band][0].shape[1:])
        for i, j, value in kept:
            expected[:, i - lo[0], j - lo[1]] += (value, value ** 2)
        assert np.allclose(sums[band][0][0], expected[0]) and np.allclose(sums[band][1][0], expected[1])


def test_error_kernels_against_exact_line_integrals():
    # each band's footprint at the probe slope and its second differences in slope and in the plane, against the
    # same made by exact line integrals (spatial sampling) at the same slopes
    wav, spacing = SplineWavelet(4), (1.0, 0.75, 1.5)
    n, u, v = view_frame(35.0, 25.0)
    view = SimpleNamespace(n=n, u=u, v=v)
    lo, step, count = np.array([-0.2, -0.15]), np.array([0.1, 0.075]), np.array([5, 5])
    bands = [(1, "aad"), (2, "dda"), (2, "aaa")]
    kernels = cone_budget.error_kernels(wav, spacing, view, bands, 0.25, lo, step, count)
    c = np.array([0.1, 0.075])  # one step in from the node farthest from the axis, (0.2, 0.15)
    slopes = np.stack([c, c + [0.1, 0], c - [0.1, 0], c + [0, 0.075], c - [0, 0.075]])
    for band in bands:
        exact = sheared_footprints(wav, spacing, n, u, v, {band: 0.25}, slopes, "spatial")[band].data.astype(float)
        g, d_u, d_v, g_uu, g_vv = kernels[band]
        peak = np.abs(exact[0]).max()
        assert np.abs(g).max() == pytest.approx(peak, rel=1e-4)
        for mine, theirs in ((d_u, exact[1] + exact[2] - 2 * exact[0]), (d_v, exact[3] + exact[4] - 2 * exact[0]),
                             (g_uu, np.diff(exact[0], 2, axis=1) / 0.25 ** 2),
                             (g_vv, np.diff(exact[0], 2, axis=0) / 0.25 ** 2)):
            assert np.abs(mine).max() == pytest.approx(np.abs(theirs).max(), rel=1e-3)
            assert np.sort(mine.ravel())[-3:] == pytest.approx(np.sort(theirs.ravel())[-3:], rel=1e-3)


def test_predicted_error_adds_the_levels_as_their_reads_do():
    # slope errors of levels at one r with their signs, of different r in magnitude; texel means with signs, their
    # spreads in squares (a hand computation on two-point images)
    a, b = (1, False), (2, False)
    errors = {a: (np.array([4e-3, 0.0]), np.array([1e-3, 0.0]), np.array([1e-3, 0.0]), np.array([4e-6, 0.0])),
              b: (np.array([-3e-3, 2e-3]), np.array([2e-3, 0.0]), np.array([-2e-3, 0.0]), np.array([5e-6, 0.0]))}
    sigmas = cone_budget.SIGMAS
    both = max(abs(4e-3 - 3e-3), abs(1e-3 + 2e-3)) + abs(1e-3 - 2e-3) + sigmas * np.sqrt(9e-6)
    assert cone_budget.predicted_error(errors, {a: (1, 1.0), b: (1, 1.0)}) == pytest.approx(max(both, 2e-3))
    apart = 4e-3 + 3e-3 / 4 + abs(1e-3 - 2e-3 / 2) + sigmas * np.sqrt(4e-6 + 5e-6 / 4)
    assert cone_budget.predicted_error(errors, {a: (1, 1.0), b: (2, 2.0 ** 0.5)}) == pytest.approx(apart)


def test_refined_bands_fit_the_share_at_least_cost(monkeypatch):
    # the greedy choice on made-up error images: it fits SHARE, leaves an errorless level alone, and no level's
    # refinement can be taken back a step and still fit; other orders than cubic are never refined
    rng = np.random.default_rng(5)
    errors = {(1, False): (rng.normal(0, 2e-3, 50), rng.normal(0, 2e-3, 50), np.zeros(50), np.zeros(50)),
              (2, False): (rng.normal(0, 6e-3, 50), rng.normal(0, 6e-3, 50), rng.normal(0, 1e-3, 50),
                           np.full(50, 4e-6)),
              (3, False): (np.zeros(50),) * 4, (3, True): (rng.normal(0, 1e-3, 50),) * 2 + (np.zeros(50),) * 2}
    monkeypatch.setattr(cone_budget, "level_errors", lambda *args: errors)
    bands = [(m, key) for m in (1, 2, 3) for key in ("aad", "ddd")] + [(3, "aaa")]
    wv = SimpleNamespace(groups=[SimpleNamespace(wavelet=SplineWavelet(4))], spacing=(1.0, 1.0, 1.0))
    view = SimpleNamespace(u=np.array([1.0, 0.0, 0.0]), v=np.array([0.0, 1.0, 0.0]))
    choice = cone_budget.refined_bands(wv, 0, view, dict.fromkeys(bands, 0.3), None, None, (3, 4))
    levels = {(m, key == "aaa"): o for (m, key), o in choice.items()}
    assert cone_budget.predicted_error(errors, dict.fromkeys(errors, (1, 1.0))) > cone_budget.SHARE
    assert cone_budget.predicted_error(errors, levels) <= cone_budget.SHARE
    assert levels[(3, False)] == (1, 1.0) and levels[(2, False)] != (1, 1.0)
    for level, (r, gain) in levels.items():
        back = [(r - 1, gain)] * (r > 1) + [(r, g) for g in cone_budget.TEXEL_GAINS if g < gain][-1:]
        assert all(cone_budget.predicted_error(errors, levels | {level: o}) > cone_budget.SHARE for o in back)
    linear = SimpleNamespace(groups=[SimpleNamespace(wavelet=SplineWavelet(2))])
    assert set(cone_budget.refined_bands(linear, 0, None, dict.fromkeys(bands), None, None, None).values()) == {
        (1, 1.0)}


def test_prediction_bounds_the_unrefined_error_of_sharp_data(monkeypatch):
    # Shepp-Logan, every coefficient, three levels: the predicted error of the unrefined view is above its error
    # against the exact line integrals, and within 2x of it (sharp: measured 0.62x)
    wv = clwave.WaveletVolume.from_volume(phantom("shepp-logan", n=32), wavelet="cubic", levels=3)
    camera = clwave.Camera(10, 60, 32, perspective=True, fov=32, distance=2.4 * 32)
    errors = cone_budget.level_errors(*_inputs(wv, camera)[:4], *_inputs(wv, camera)[4:])
    predicted = cone_budget.predicted_error(errors, dict.fromkeys(errors, (1, 1.0)))
    monkeypatch.setattr(perspective, "refined_bands", lambda wv, group, view, texels, *a: dict.fromkeys(texels,
                                                                                                        (1, 1.0)))
    exact = _exact_fine(wv, camera)
    actual = np.abs(clwave.splat(wv, camera).image - exact).max() / exact.max()
    assert actual < predicted < 2.0 * actual


def test_smooth_data_is_not_refined_and_meets_the_bound_at_15_degrees():
    # a smooth volume at three levels (a Gaussian blob of anisotropic voxels): its detail bands are small, so the
    # rule refines nothing, and the view still meets 1e-2 against the exact line integrals over a 15-degree cone
    z, y, x = np.meshgrid(*(np.linspace(-1, 1, k) for k in (28, 32, 30)), indexing="ij")
    data = np.exp(-(x ** 2 + 1.5 * y ** 2 + z ** 2) / 0.4).astype(np.float32)
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data, spacing=(1.5, 1.0, 1.2)), levels=3)
    camera = clwave.ConeBeam(90.0, 135.0, 32, pixel=135.0 * np.tan(np.radians(15.0)) / 16, azimuth=30,
                             elevation=20)
    renderer = clwave.SplatRenderer(wv)
    assert set(renderer.begin(camera).tables[0].refined.values()) == {(1, 1.0)}
    exact = _exact_fine(wv, camera)
    view = camera.view(wv)
    cos = -(view.rays() @ view.n)
    assert np.degrees(np.arccos(cos[exact[..., 0] > 1e-2 * exact.max()].min())) > 12.0  # the content fills the cone
    assert np.abs(renderer.render(camera).image - exact).max() <= BOUND * exact.max()
