"""Splatting's error estimate (clwave/splat/estimate.py, docs/splatting.md §5): each band's footprint energy
against the brute-force projection of its function, and the estimate of each frame, made without the final image,
against the measured error on seeded random volumes that the margins were not calibrated on."""

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

import clwave
from clwave.io.phantoms import phantom
from clwave.model.bspline import wavelet_for
from clwave.splat.estimate import band_energies

pytestmark = pytest.mark.opencl


def _view(azimuth, elevation):
    return clwave.Camera(azimuth, elevation, 8).view(clwave.Volume(np.zeros((4, 4, 4), np.float32)))


@pytest.mark.parametrize("order", [2, 4, 6])
def test_band_energies_are_the_projected_functions_energies(order):
    # float64 oracle: the projection of each prototype along an oblique ray by quadrature, its energy over the
    # image plane; and along z the closed form, ||G_x||^2 ||G_y||^2 with phi integrating to 1 and psi to 0
    wav = wavelet_for(order)
    view = _view(30.0, 20.0)
    got = band_energies(wav, (1.0, 1.0, 1.0), view)[:8]
    h = {2: 0.1, 4: 0.2, 6: 0.4}[order]  # smoother functions: coarser quadrature, the same accuracy (order 6's psi,
    #                                      11 lattice steps wide, was 20 % off on a 64-point slice grid)
    reach = np.sqrt(3.0) * max(wav.support("a"), wav.support("d")) / 2 + 1.0
    s = np.arange(-reach, reach + h / 2, h)
    S, T, R = np.meshgrid(s, s, s, indexing="ij", sparse=True)
    points = [view.u[a] * S + view.v[a] * T + view.n[a] * R for a in range(3)]
    values = {letter: [wav.prototype(letter, p + wav.support(letter) / 2.0) for p in points] for letter in "ad"}
    for code in range(8):
        f = values["ad"[code & 1]][0] * values["ad"[code >> 1 & 1]][1] * values["ad"[code >> 2 & 1]][2]
        projection = f.sum(axis=2) * h
        np.testing.assert_allclose(got[code], np.sum(projection ** 2) * h * h, rtol=0.03)
    along_z = band_energies(wav, (1.0, 1.0, 1.0), _view(0.0, 90.0))
    norms = np.array([wav.norm(letter) ** 2 for letter in "ad"])
    np.testing.assert_allclose(along_z[8:12] / 2, np.outer(norms, norms).reshape(-1)[[0, 2, 1, 3]], rtol=0.03)
    assert not along_z[12:16].any()  # psi along the ray projects to nothing


def _volumes():
    # none of these tuned the margins (docs/splatting.md §5): smooth and white-noise random, a Shepp-Logan phantom,
    # and the phantom as a CT's thick slices (3:1 spacing)
    rng = np.random.default_rng(2026)
    yield clwave.Volume(gaussian_filter(rng.standard_normal((20, 20, 20)), 1.5).astype(np.float32))
    yield clwave.Volume(rng.random((16, 16, 16)).astype(np.float32))
    yield phantom("shepp-logan", 20)
    yield clwave.Volume(phantom("shepp-logan", 24).data[::3].copy(), spacing=(3.0, 1.0, 1.0))


def _projection(kind, volume):
    if kind == "orthographic":
        return clwave.Camera(40, 25, 20)
    extent = float(np.max(np.array(volume.shape) * np.array(volume.spacing)))  # a cone of about 10 degrees
    return clwave.ConeBeam(3 * extent, 4.5 * extent, 20, pixel=1.3 * 4.5 * extent / 3 / 20, azimuth=40, elevation=25)


@pytest.mark.parametrize("kind", ["orthographic", "cone"])
def test_the_estimate_bounds_the_measured_error_within_4x(kind):
    # issue #30's bar, for RMS and max: the estimate at least the measured error on >= 95 % of the intermediate
    # frames and at most 4x it on >= 95 %, made without the final image
    _assert_the_bar([(volume, _projection(kind, volume)) for volume in _volumes()])


def test_the_estimate_holds_on_cells_of_several_pixels():
    # the bar as above on images wider than the estimate's grid (cells of 3 pixels a side, docs/splatting.md §5)
    from clwave.splat.estimate import GRID

    size, cases = 3 * GRID, []
    for volume in (clwave.Volume(gaussian_filter(np.random.default_rng(5).standard_normal((24, 24, 24)), 1.0)
                                 .astype(np.float32)), phantom("shepp-logan", 24)):
        extent = float(np.max(volume.shape))
        cases += [(volume, clwave.Camera(40, 25, size)),
                  (volume, clwave.ConeBeam(3 * extent, 4.5 * extent, size, pixel=1.95 * extent / size, azimuth=40))]
    _assert_the_bar(cases)
    # a side that the cells do not divide (65 = 32 cells of 2 pixels and one of 1): the obliquity at each cell
    wv = clwave.WaveletVolume.from_volume(phantom("shepp-logan", 16), levels=1).threshold(keep=0.3)
    for camera in (clwave.Camera(30, 20, size=(GRID + 1, GRID + 3), perspective=True, fov=40),
                   clwave.ConeBeam(48, 72, GRID + 1, pixel=0.5)):
        frames = list(clwave.progressive(wv, camera, steps=3))
        assert all(np.isfinite(f.estimated_relative_rms_error) for f in frames)


def test_the_estimate_holds_on_four_channel_cone_views():
    # the bar as above on channels of unlike detail (smooth random at four widths, the first the roughest), three
    # levels, cone beams: each channel's error has its own details' energy (docs/splatting.md §5; spread evenly over
    # the channels, the max estimate was under the error on 10 of the 56 frames with cones of 12 and 4.6 degrees, then
    # 1). Cones of 6.2 and 4.6 degrees (f = 6, 8): at 12 (f = 3) the refined level 3 of the smoothest channel took
    # 773 M texels (2.9 GiB), more than PoCL allows on some CI machines (docs/known-gaps.md §13)
    rng = np.random.default_rng(3)
    volume = clwave.Volume(np.stack([gaussian_filter(rng.standard_normal((24, 24, 24)), width)
                                     for width in (1.0, 1.5, 2.0, 3.0)], -1).astype(np.float32))
    _assert_the_bar([(volume, clwave.ConeBeam(f * 24, 1.5 * f * 24, 32, pixel=1.3 * 1.5 * 24 / 32, azimuth=azimuth,
                                              elevation=25)) for f in (6.0, 8.0) for azimuth in (40, 130)], levels=3)


def test_the_estimate_holds_for_order_6_on_smooth_and_noisy_volumes():
    # the bar as above for the quintic wavelet (detail supports of 11 lattice steps, the cubic 7), orthographic and
    # cone beam
    rng = np.random.default_rng(6)
    cases = []
    for volume in (clwave.Volume(gaussian_filter(rng.standard_normal((20, 20, 20)), 1.5).astype(np.float32)),
                   clwave.Volume(rng.random((16, 16, 16)).astype(np.float32))):
        cases += [(volume, _projection("orthographic", volume)), (volume, _projection("cone", volume))]
    _assert_the_bar(cases, wavelet="quintic")


def test_the_estimate_holds_for_order_6_on_piecewise_constant_volumes():
    # the bar as above for the quintic wavelet on Shepp-Logan 32^3 at four angles and two cone beams, 32^2: early
    # frames there are up to 7 times the final image, their overshoot taken back by the coarse details' rest, which an
    # energy density drew as noise and left in the predicted final peak (docs/splatting.md §5; the estimate before
    # was under the error on 11 of these 84 frames, max and RMS alike; drawn signed, on none)
    volume = phantom("shepp-logan", 32)
    cases = [(volume, clwave.Camera(azimuth, elevation, 32))
             for azimuth, elevation in ((30, 20), (0, 0), (75, 60), (130, -40))]
    cases += [(volume, clwave.ConeBeam(f * 32, 1.5 * f * 32, 32, pixel=1.3 * 1.5 * 32 / 32, azimuth=40, elevation=25))
              for f in (5.0, 8.0)]  # cones of 7.4 and 4.6 degrees: at 12 (f = 3) 357 M texels, over 1 GiB
    _assert_the_bar(cases, wavelet="quintic")


def test_the_signed_rest_is_the_splatted_rest():
    # the estimate's signed map against the splatter's image of the same coefficients (final - frame), where the
    # cells resolve every band (pixels of 0.6 voxel, one a cell): orthographic, and a cone beam to first order in
    # each footprint's magnification and ray slopes (measured: 0.2-0.4 % and 0.8-3.4 % of the error; the cone's 4-18 %
    # without those terms)
    from clwave.splat.estimate import SplatEstimate
    from clwave.splat.renderer import SplatRenderer

    volume = phantom("shepp-logan", 16)
    wv = clwave.WaveletVolume.from_volume(volume, wavelet="quintic", levels=2).threshold(keep=0.3)
    r = SplatRenderer(wv)
    for camera, within in ((clwave.Camera(130, -40, 40, extent=24.0), 0.01),
                           (clwave.ConeBeam(8 * 16, 12 * 16, 40, pixel=0.9, azimuth=40, elevation=25), 0.05)):
        frames = list(clwave.progressive(wv, camera, steps=6, renderer=r))
        estimate = SplatEstimate(r, r.begin(camera).view)
        group = estimate.groups[0]
        assert estimate.cell == 1 and np.all(group["layer"][np.unique(group["band"])] >= 0)  # every band signed
        for frame in frames[1:-1]:
            estimate.add(frame.image, frame.coefficients)
            error = frame.error_image()[..., 0]
            signed = estimate.maps()[0][..., 0]
            assert np.linalg.norm(signed - error) <= within * np.linalg.norm(error), frame.index


def _assert_the_bar(cases, levels=2, wavelet="cubic"):
    """Issue #30's bar over the intermediate frames of each (volume, camera) at 5 % and 30 % kept, RMS and max."""
    rms, top = [], []
    for volume, camera in cases:
        wv = clwave.WaveletVolume.from_volume(volume, wavelet=wavelet, levels=levels)
        for keep in (0.05, 0.3):
            for frame in list(clwave.progressive(wv.threshold(keep=keep), camera, steps=8))[:-1]:
                f = frame.figures()
                rms.append(f["estimated_relative_rms_error"] / f["relative_rms_error"])
                top.append(f["estimated_relative_max_error"] / f["relative_max_error"])
    for ratio in (np.array(rms), np.array(top)):
        assert len(ratio) >= 50 and np.all(np.isfinite(ratio))
        assert np.mean(ratio >= 1) >= 0.95 and np.mean(ratio <= 4) >= 0.95, np.sort(ratio)


def test_a_zoomed_view_keeps_the_estimate_small(monkeypatch):
    # the widest footprint over 3 image widths: cells of several pixels keep the margin within GRID cells (it grew
    # as the zoom, the maps with its square), and the estimates still bound the error (RMS and max, within 4x)
    from clwave.splat import estimate

    made, init = [], estimate.SplatEstimate.__init__
    monkeypatch.setattr(estimate.SplatEstimate, "__init__", lambda self, r, view: (init(self, r, view),
                                                                                  made.append(self))[0])
    wv = clwave.WaveletVolume.from_volume(phantom("marschner-lobb", 16), levels=3).threshold(keep=0.3)
    frames = list(clwave.progressive(wv, clwave.Camera(30, 20, 64, extent=3.0), steps=6))[:-1]
    assert made[0].cell > 1 and made[0].pad <= estimate.GRID + 2
    for f in (frame.figures() for frame in frames):
        for kind in ("rms", "max"):
            assert 1 <= f[f"estimated_relative_{kind}_error"] / f[f"relative_{kind}_error"] <= 4, f


def test_error_stops_at_the_first_frame_estimated_within_it():
    volume = clwave.Volume(gaussian_filter(np.random.default_rng(7).standard_normal((20, 20, 20)), 1.5)
                           .astype(np.float32))
    wv = clwave.WaveletVolume.from_volume(volume, levels=2).threshold(keep=0.3)
    camera = clwave.Camera(20, 35, 20)
    every = list(clwave.progressive(wv, camera, steps=8))
    assert every[-1].estimated_relative_rms_error == 0 == every[-1].relative_rms_error
    one_shot = clwave.splat(wv, camera).image  # the frames splat in ranges: the sums' order differs from one shot
    np.testing.assert_allclose(every[-1].image, one_shot, rtol=1e-5, atol=1e-6 * np.abs(one_shot).max())
    target = 0.1
    stopped = list(clwave.progressive(wv, camera, steps=8, error=target))
    first = next(f for f in every if f.estimated_relative_rms_error <= target)
    assert len(stopped) == first.index + 1 < len(every) - 1 and stopped[-1].estimated_relative_rms_error <= target
    assert all(f.estimated_relative_rms_error > target for f in stopped[:-1])
    assert stopped[-1].relative_rms_error <= target  # the frame it stops at is within E, as estimated


def test_band_energies_at_anisotropic_spacing():
    # float64 oracle as above, on voxels 4x as wide along x (a CT's slices): the bands' energies relative to the
    # approximation's (the world's factor apart), whose finest spectral lobe the slice grid must resolve
    wav, view, d = wavelet_for(4), _view(30.0, 20.0), np.array([4.0, 1.0, 1.0])  # x, y, z
    got = band_energies(wav, (1.0, 1.0, 4.0), view)[:8]
    h = 0.5
    reach = np.sqrt(3.0) * max(wav.support("a"), wav.support("d")) * d.max() / 2 + 1.0
    s = np.arange(-reach, reach + h / 2, h)
    S, T, R = np.meshgrid(s, s, s, indexing="ij", sparse=True)
    points = [(view.u[a] * S + view.v[a] * T + view.n[a] * R) / d[a] for a in range(3)]
    values = {letter: [wav.prototype(letter, p + wav.support(letter) / 2.0) for p in points] for letter in "ad"}
    want = np.array([np.sum((values["ad"[c & 1]][0] * values["ad"[c >> 1 & 1]][1]
                             * values["ad"[c >> 2 & 1]][2]).sum(axis=2) ** 2) for c in range(8)])
    np.testing.assert_allclose(got / got[0], want / want[0], rtol=0.03)


def test_the_signed_rest_holds_on_cells_of_several_voxels(monkeypatch):
    # cells of 3.5 voxels, as 128^3 on 64 cells at 512^2 (here 32^3 on 16 cells at 64^2): the signed map's cell means
    # against the splatter's rest (final - frame) averaged over the same cells.  Deposited bilinearly on such cells,
    # the approximation's large quintic coefficients of both signs aliased into the footprints' passband (up to 3.2
    # times the rest measured; on split cells 0.37 at most, docs/splatting.md §5)
    from clwave.splat import estimate
    from clwave.splat.renderer import SplatRenderer

    monkeypatch.setattr(estimate, "GRID", 16)
    wv = clwave.WaveletVolume.from_volume(phantom("shepp-logan", 32), wavelet="quintic", levels=2).threshold(keep=0.3)
    r = SplatRenderer(wv)
    camera = clwave.Camera(130, -40, 64)
    frames = list(clwave.progressive(wv, camera, steps=8, renderer=r))
    est = estimate.SplatEstimate(r, r.begin(camera).view)
    assert est.cell == 4 and est.fine == 2 == est.split
    for frame in frames[1:-1]:
        est.add(frame.image, frame.coefficients)
        rest = frame.error_image()[..., 0].reshape(16, 4, 16, 4).mean(axis=(1, 3))
        signed = est.maps()[0][..., 0]
        assert np.linalg.norm(signed - rest) <= 0.5 * np.linalg.norm(rest), frame.index
        f = frame.figures()
        for kind in ("rms", "max"):
            assert 1 <= f[f"estimated_relative_{kind}_error"] / f[f"relative_{kind}_error"] <= 4, (frame.index, f)
