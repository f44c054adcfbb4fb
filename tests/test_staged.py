"""The first image from a ``.clw`` file at once (clwave/raytrace/staged.py, docs/raytracing.md §8): the
approximation read alone against the whole file's, the content mask read a layer of chunks at a time against
the mask it was written from, the file's occupancy of the approximation against the mask's by brute force, the
coarse stage's X-ray colours against the reference (wavelet) field of the approximation, its frames' estimates
against their measured error on sparse models, and the staged frames ending bit for bit at the whole file's
direct render."""

import ctypes
import os
import shutil

import h5py
import numpy as np
import pytest

import clwave
from clwave import WaveletVolume
from clwave.device import memory
from clwave.io.clw import MASK_CHUNK
from clwave.io.occupancy import OccupancyGrid, mass_on_occupied
from clwave.io.summary import approximation_occupancy, detail_energy, detail_levels
from clwave.model.wavelet import importance_of
from clwave.raytrace import bricks, passes
from clwave.raytrace.coarse_estimate import approximation_grid, detail_share, field_energy, line_energy, white_share
from clwave.raytrace.staged import StagedTracer, coarse_volume
from clwave.raytrace.tracer import RayTracer
from clwave.threads import Abandoned
from test_bricks import out_of_core_model, smooth_rgba, smooth_volume
from test_progressive_raytrace import model

pytestmark = pytest.mark.opencl


@pytest.fixture(scope="module", params=["cubic", ["cubic", "cubic", "cubic", "linear"]])
def model_file(tmp_path_factory, request):
    """RGBA with a content mask; one order (the coarse stage a coarser volume), or mixed orders (the coarse stage
    the bricks of the coarsest detail)."""
    rgba = smooth_rgba(n=32, empty_corner=True)
    path = tmp_path_factory.mktemp("staged") / "model.clw"
    WaveletVolume.from_volume(rgba, wavelet=request.param, levels=3).threshold(keep=0.1).save(path)
    return path


def test_the_approximation_alone_is_the_approximation_band_of_the_file(model_file):
    whole, coarse = WaveletVolume.open(model_file), WaveletVolume.open(model_file, approximation=True)
    for g, a in zip(whole.groups, coarse.groups):
        band = g.band_slices()[0]
        assert a.kept == band.stop - band.start > 0
        assert np.array_equal(a.all_positions(), g.all_positions()[band])
        assert np.array_equal(a.values, g.values[:, band])
    assert coarse.levels == whole.levels and coarse.content == whole.content


@pytest.mark.parametrize("wavelet", ["cubic", "linear", "haar"])
def test_the_coarse_volume_is_the_approximations_field(tmp_path, wavelet):
    """The approximation of L levels as a level-0 model of a volume 2^L times coarser: the closed-form field
    (``evaluate``) at random world points, on an anisotropic volume off the origin."""
    vol = smooth_volume(n=40, channels=2)
    vol = clwave.Volume(vol.data[:, :36, :33], spacing=(0.7, 1.3, 0.9), origin=(4.0, -2.0, 7.5))
    WaveletVolume.from_volume(vol, wavelet=wavelet, levels=2).threshold(keep=0.2).save(tmp_path / "m.clw")
    approximation = WaveletVolume.open(tmp_path / "m.clw", approximation=True)
    coarse = coarse_volume(approximation)
    assert coarse.levels == 0 and coarse.shape == approximation.groups[0].bands[0].shape
    lo, hi = np.array(vol.origin) - 25, np.array(vol.origin) + 25
    points = np.random.default_rng(5).uniform(lo, hi, (300, 3))
    ref = approximation.evaluate(points)
    assert np.abs(ref).max() > 0.1
    np.testing.assert_allclose(coarse.evaluate(points), ref, rtol=0, atol=1e-6 * np.abs(ref).max())
    assert np.array_equal(coarse.content_box(), approximation.content_box())


def test_the_energy_of_the_details_is_read_from_the_tiers_alone(model_file):
    """detail_energy against the sum of the squared importances of the whole file's details (a tier counts each
    within 9/8 of its square: 3 mantissa bits, linear within an octave; so the two agree within that);
    StagedTracer.missing is the share of the details' (detail_field: the coarsest level's as a field,
    tests/test_detail_field.py) in theirs and the approximation's field energy, the latter the sum of squares of the
    approximation's field on the lattice (reconstructed; scaled to the importances' largest channel as their sum over
    the coefficients)."""
    whole = WaveletVolume.open(model_file)
    parts = [importance_of(g, None, whole.frame).astype(np.float64) ** 2 for g in whole.groups]
    details = sum(p.sum() - p[g.band_slices()[0]].sum() for p, g in zip(parts, whole.groups))
    assert details > 0 and 8 / 9 <= detail_energy(model_file) / details <= 9 / 8
    approximation = WaveletVolume.open(model_file, approximation=True)
    approximation.content_mask = None
    step = 4  # the level-3 field is smooth at 8 cells: a midpoint sum of 4-cell steps, past the support
    axes = [np.arange(-14, n + 14, step) - (n - 1) / 2 for n in approximation.shape[::-1]]  # x y z
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    voxels = approximation.evaluate(approximation.origin + grid * approximation.spacing[::-1]).astype(np.float64)
    field = 0.0
    for g in approximation.groups:
        importances = np.sum(importance_of(g, None, approximation.frame).astype(np.float64) ** 2)
        coefficients = np.sum(g.values.astype(np.float64) ** 2) * g.wavelet.norm_phi ** 6
        field += np.sum(voxels[:, list(g.channels)] ** 2) * step ** 3 * importances / coefficients
    missing, unread = RayTracer.open(model_file).missing, sum(detail_levels(model_file))
    assert abs(missing ** 2 - unread / (unread + field)) <= 0.02 * missing ** 2


def brute_occupancy(mask, wavelet, level, shape) -> np.ndarray:
    """Coefficient k of the level: whether one of the 2^L voxels at the centre of the (2^L - 1) j + 1 fine
    B-splines its subdivision makes (from voxel o_L + 2^L k) is in the mask, one coefficient at a time."""
    step, n = 2 ** level, (2 ** level - 1) * wavelet.order + 1
    out = np.zeros(shape, bool)
    for k in np.ndindex(*shape):
        lo = [wavelet.offset("a", level) + step * i + (n - step) // 2 for i in k]
        box = tuple(slice(max(a, 0), max(a + step, 0)) for a in lo)
        out[k] = mask[box].any()
    return out


def test_the_file_holds_the_occupancy_of_its_approximation(model_file, tmp_path):
    """What the writer stores per group (its own wavelet's level rule) against the content mask by brute force;
    the accumulator fed boxes of any size in any order gives the same."""
    whole = WaveletVolume.open(model_file)
    mask, stored = np.asarray(whole.content_mask), approximation_occupancy(model_file)
    for g, occupied in zip(whole.groups, stored, strict=True):
        want = brute_occupancy(mask, g.wavelet, whole.levels, g.bands[0].shape)
        assert want.any() and not want.all() and np.array_equal(occupied, want)
        grid, rng = OccupancyGrid(g.wavelet, whole.levels, g.bands[0].shape), np.random.default_rng(4)
        cuts = [np.unique(np.r_[0, rng.integers(1, n, 3), n]) for n in mask.shape]
        boxes = [(a, b, c) for a in zip(cuts[0], cuts[0][1:]) for b in zip(cuts[1], cuts[1][1:])
                 for c in zip(cuts[2], cuts[2][1:])]
        for i in rng.permutation(len(boxes)):
            grid.add([lo for lo, _ in boxes[i]], mask[tuple(slice(lo, hi) for lo, hi in boxes[i])])
        assert np.array_equal(grid.grid, want)


@pytest.mark.parametrize("wavelet", ["haar", "linear", "quadratic", "cubic", "quintic"])
def test_the_mass_on_occupied_blocks_is_the_splines_integral_over_them(wavelet):
    """mass_on_occupied against a midpoint sum of the closed-form B-spline over its support, each fine cell
    counted where the coefficient owning its central block (every 2^L voxels from the level's central start) is
    occupied; the product of the axes' sums, summed over the occupied owners of a random grid."""
    wav, level = clwave.model.bspline.SplineWavelet(clwave.model.bspline.WAVELET_ORDERS[wavelet]), 2
    step, j = 2 ** level, wav.order
    occupied = np.random.default_rng(2).random((5, 6, 7)) < 0.4
    n = (step - 1) * j + 1  # the refinement's fine B-splines; the central 2^L start (n - 2^L) // 2 after the first
    centre = wav.offset("a", level) + (n - step) // 2
    x = (np.arange(64 * step * j) + 0.5) / 64  # midpoints over the support in fine cells
    weight = wav.phi(x / step) / step / 64

    def shares(axis_occupied):  # per coefficient k along one axis
        out = np.zeros(len(axis_occupied))
        for k in range(len(axis_occupied)):
            owner = np.floor((wav.offset("a", level) + step * k + x - centre) / step).astype(int)
            inside = (owner >= 0) & (owner < len(axis_occupied))
            out[k] = np.sum(weight[inside] * axis_occupied[owner[inside]])
        return out

    want = np.zeros(occupied.shape)
    for k in np.ndindex(*occupied.shape):  # the whole grid: the product weights over every occupied owner
        w = [shares(np.eye(n_, dtype=bool)[i]) for n_, i in zip(occupied.shape, k)]
        want += occupied[k] * np.einsum("a,b,c->abc", *w)
    np.testing.assert_allclose(mass_on_occupied(occupied, wav, level), want, atol=1e-3)


def test_the_content_mask_is_read_a_layer_of_chunks_at_a_time(tmp_path):
    data = np.random.default_rng(3).uniform(0, 1, (2 * MASK_CHUNK[0] + 9, 6, 11)).astype(np.float32)
    data[data < 0.3] = 0
    path = tmp_path / "tall.clw"
    WaveletVolume.from_volume(data, wavelet="linear", levels=1).save(path)
    mask = WaveletVolume.open(path).content_mask
    assert not mask.read.any()
    z = MASK_CHUNK[0] + 5
    assert np.array_equal(mask.box((z, -2, 3), (7, 9, 20)),
                          np.pad(data != 0, ((0, 0), (2, 1), (0, 12)))[z:z + 7, :, 3:23])
    assert mask.read.tolist() == [False, True, False]
    assert np.array_equal(np.asarray(mask), data != 0) and mask.read.all()


def test_staged_frames_start_coarse_and_end_at_the_direct_render_bit_for_bit(model_file):
    staged = RayTracer.open(model_file)
    cam = clwave.Camera(25, 15, size=16)
    # the coarse stage: the approximation's field (no content clamp), every channel
    approximation = WaveletVolume.open(model_file, approximation=True)
    approximation.content_mask = None
    ref = RayTracer(approximation, field="wavelet").render(cam, tolerance=1e-4, absorption=False)
    xray = staged.coarse.render(cam, tolerance=1e-3, absorption=False, detail=staged.coarse_detail)
    colours = 3 if staged.coarse.lod else 4  # the coarsest detail's bricks clamp alpha at 0 (raytracing.md §8)
    assert np.abs(ref.image).max() > 0.1
    assert np.max(np.abs(xray.image - ref.image)[..., :colours]) <= 1.1e-3
    cam = clwave.Camera(25, 15, size=64)  # coarse frames on 32^2 and 64^2 (no side below MIN_SIDE)
    frames = list(staged.refine(cam, tolerance=1e-3))
    assert frames[0].meta["stage"] == "coarse" and frames[0].reduction == 2 and frames[0].detail == 3
    assert frames[-1].meta["stage"] == "full" and frames[-1].estimated_relative_rms_error == 0
    assert staged.coarse is None and [f.index for f in frames] == list(range(len(frames)))
    for f in frames[:-1]:  # the coarse frames' estimates see the details they lack (docs/raytracing.md §9)
        if f.meta["stage"] == "full":
            continue  # a full-stage preview: held to [1, 4] of its error below
        figures = f.figures()
        assert figures["estimated_relative_rms_error"] >= figures["relative_rms_error"], figures
        assert figures["estimated_relative_max_error"] >= figures["relative_max_error"], figures
    direct = RayTracer(WaveletVolume.open(model_file)).render(cam, tolerance=1e-3)
    assert np.array_equal(frames[-1].image, direct.image)
    assert staged.render(cam, tolerance=1e-3).meta["stage"] == "full"


def coarse_figures(path, camera, monkeypatch, **options) -> list:
    """The figures of the staged tracer's coarse frames of ``camera`` (both: the full stage not ready until they
    are made), measured against the whole file's direct render."""
    with monkeypatch.context() as patch:
        patch.setattr(StagedTracer, "ready", property(lambda self: False))
        return [f.figures() for f in RayTracer.open(path).refine(camera, tolerance=1e-2, **options)
                if f.meta["stage"] == "coarse"]


def test_the_coarse_frames_estimate_bounds_their_error(tmp_path, monkeypatch):
    """Over hydrogen, Marschner-Lobb, a random smooth volume and the MNI152 MRI (48^3), 5 % and 0.5 % kept, at 128^2,
    shaded and X-ray: every coarse frame's RMS and max estimates at least its measured error, and both at most 4
    times it on at least 95 % of the 32 frames (31: Marschner-Lobb's X-ray frame at 5 % reads 4.03x in RMS).  At
    0.5 % no detail is missing: the error is the content clamp the coarse stage goes without; at 5 % the details
    dominate, their size from the coarsest level's field energy the file holds and the approximation's, in X-ray
    frames both weighed by the share the line integrals keep (docs/raytracing.md §9: 49 of 96 frames in [1, 4]
    before the field energy, 92 now)."""
    ratios = []
    for name in ("hydrogen", "marschner-lobb", "random", "mri"):
        for keep in (0.05, 0.005):
            path = tmp_path / f"{name}_{keep}.clw"
            model(name, keep=keep).save(path)
            for absorption in (True, False):
                for f in coarse_figures(path, clwave.Camera(30, 20, size=128), monkeypatch, absorption=absorption):
                    ratios.append((f["estimated_relative_rms_error"] / f["relative_rms_error"],
                                   f["estimated_relative_max_error"] / f["relative_max_error"], name, keep))
    assert len(ratios) == 32
    assert all(rms >= 1 and top >= 1 for rms, top, _, _ in ratios), ratios
    assert sum(rms <= 4 and top <= 4 for rms, top, _, _ in ratios) >= 31, ratios


def test_kept_details_and_the_clamp_are_not_counted_twice_in_a_shaded_frame(tmp_path, monkeypatch):
    """Where details are kept they cancel the approximation's haze off the content, which the clamp removes (the
    clamp alone changes hydrogen 256^3's 128^2 image at 5 % by 0.4 % of what the details do): a shaded coarse frame
    takes the larger of the two terms, not both.  Hydrogen 128^3 at 5 % (rho 0.12, kappa 0.07) to 256^2: a case of
    the held-out set the change was judged on (tools/staged_estimate.py --held-out), pinned here; both coarse frames
    within [1, 4] of their error (RMS 4.05x and more with both terms; docs/raytracing.md §9)."""
    path = tmp_path / "hydrogen.clw"
    rgba = clwave.TransferFunction.preset("hydrogen").classify(clwave.phantom("hydrogen", n=128))
    WaveletVolume.from_volume(rgba, wavelet="cubic", levels=3).threshold(keep=0.05).save(path)
    frames = coarse_figures(path, clwave.Camera(30, 20, size=256), monkeypatch, absorption=True)
    assert len(frames) == 2
    for f in frames:
        for n in ("rms", "max"):
            assert 1 <= f[f"estimated_relative_{n}_error"] / f[f"relative_{n}_error"] <= 4, f


def test_xray_coarse_frames_of_other_geometries_bound_their_error(tmp_path, monkeypatch):
    """The X-ray estimate takes the approximation's line-integral energy from the frame's own image: a perspective
    camera (its pixels' area at the target), a cone beam of rectangular pixels and a view cropping the volume (the
    part in view against all the details) keep their coarse frames' estimates at least their errors, the RMS
    within 4 times it (hydrogen 48^3)."""
    path = tmp_path / "hydrogen.clw"
    model("hydrogen", keep=0.05).save(path)
    cameras = (clwave.Camera(30, 20, size=128, perspective=True), clwave.Camera(30, 20, size=128, extent=30.0),
               clwave.ConeBeam(150.0, 225.0, (128, 112), pixel=(0.9, 0.75), azimuth=30, elevation=20))
    for cam in cameras:
        frames = coarse_figures(path, cam, monkeypatch, absorption=False)
        assert len(frames) == 2
        for f in frames:
            assert 1 <= f["estimated_relative_rms_error"] / f["relative_rms_error"] <= 4, (cam, f)
            assert f["estimated_relative_max_error"] >= f["relative_max_error"], (cam, f)


def test_a_file_without_the_occupancy_opens_and_renders_as_before(tmp_path, monkeypatch):
    """A file written before the occupancy: the coarse stage the same, its estimate without the clamp's term, the
    last frame the direct render."""
    path, old = tmp_path / "new.clw", tmp_path / "old.clw"
    model("hydrogen", n=24, keep=0.005).save(path)
    shutil.copy(path, old)
    with h5py.File(old, "r+") as h5:
        del h5["g0/occupancy"]
    assert approximation_occupancy(old) == [None]
    assert RayTracer.open(old).outside == 0 < RayTracer.open(path).outside
    cam = clwave.Camera(30, 20, size=64)
    new_frames, old_frames = coarse_figures(path, cam, monkeypatch), coarse_figures(old, cam, monkeypatch)
    for n, o in zip(new_frames, old_frames, strict=True):
        assert n["relative_rms_error"] == o["relative_rms_error"]  # the same image
        assert o["estimated_relative_rms_error"] < n["estimated_relative_rms_error"]
    last = list(RayTracer.open(old).refine(cam, tolerance=1e-2))[-1]
    assert np.array_equal(last.image, RayTracer(WaveletVolume.open(path)).render(cam, tolerance=1e-2).image)


def test_a_file_without_the_details_field_energy_opens_and_renders_as_before(tmp_path, monkeypatch):
    """A file written before g<i>/detail_field: the details' importance energy from the tiers (the tenth session's
    estimate, higher where the details cancel), the same coarse images, the last frame the direct render."""
    path, old = tmp_path / "new.clw", tmp_path / "old.clw"
    model("random", keep=0.05).save(path)
    shutil.copy(path, old)
    with h5py.File(old, "r+") as h5:
        del h5["g0/detail_field"]
    assert detail_levels(old) is None and sum(detail_levels(path)) < detail_energy(path)
    staged = RayTracer.open(old)
    field = (1 - staged.missing ** 2) / staged.missing ** 2 * detail_energy(old)  # from missing, as it was made
    unread = sum(detail_levels(path))
    assert RayTracer.open(path).missing ** 2 == pytest.approx(unread / (field + unread))
    cam = clwave.Camera(30, 20, size=64)
    for n, o in zip(coarse_figures(path, cam, monkeypatch), coarse_figures(old, cam, monkeypatch), strict=True):
        assert n["relative_rms_error"] == o["relative_rms_error"]  # the same image
        assert n["estimated_relative_rms_error"] < o["estimated_relative_rms_error"]
    last = list(RayTracer.open(old).refine(cam, tolerance=1e-2))[-1]
    assert np.array_equal(last.image, RayTracer(WaveletVolume.open(path)).render(cam, tolerance=1e-2).image)


@pytest.mark.parametrize("model_file", ["cubic"], indirect=True)  # the refinement is the same for both
def test_a_ready_staged_tracer_refines_as_the_whole_files_tracer(model_file):
    """Once the full stage is ready, refine is RayTracer.refine of the whole file: the same previews (images and
    estimates, each estimate within [1, 4] of its measured error, RMS and max), the same final image; error= stops
    at the first frame whose estimate reaches it."""
    staged, cam = RayTracer.open(model_file), clwave.Camera(-40, 25, size=256)
    staged.wait()
    frames = list(staged.refine(cam, tolerance=1e-3))
    ordinary = list(RayTracer(WaveletVolume.open(model_file)).refine(cam, tolerance=1e-3))
    assert [(f.index, f.reduction, f.meta["stage"]) for f in frames] == [(0, 8, "full"), (1, 4, "full"), (2, 1, "full")]
    for f, o in zip(frames, ordinary, strict=True):
        assert np.array_equal(f.image, o.image)
        assert (f.estimated_relative_rms_error, f.estimated_relative_max_error) == (o.estimated_relative_rms_error,
                                                                                  o.estimated_relative_max_error)
    for f in frames[:-1]:
        figures = f.figures()
        for n in ("rms", "max"):
            assert 1 <= figures[f"estimated_relative_{n}_error"] / figures[f"relative_{n}_error"] <= 4, figures
    stopped = list(staged.refine(cam, tolerance=1e-3, error=frames[1].estimated_relative_rms_error))
    assert len(stopped) == 2 and np.array_equal(stopped[-1].image, frames[1].image)


@pytest.mark.parametrize("model_file", ["cubic"], indirect=True)  # the refinement is the same for both
@pytest.mark.parametrize("ready, stages", [
    ("after the first coarse frame", [("coarse", 8), ("full", 8), ("full", 4), ("full", 1)]),
    ("after the coarse frames", [("coarse", 8), ("coarse", 4), ("full", 4), ("full", 1)])])
def test_a_full_stage_ready_during_refine_continues_with_its_previews(model_file, monkeypatch, ready, stages):
    """The full stage set up between two frames, or only once the coarse frames are made: its previews follow the
    coarse frames from the size of the last (docs/raytracing.md §8), each frame's measured error from the last
    coarse one on below the one before, the full stage's estimates within [1, 4] of theirs, the last the direct
    render bit for bit.  (The second coarse frame is not nearer than the first: its error is the details it lacks.)"""
    staged, cam = RayTracer.open(model_file), clwave.Camera(30, 20, size=256)
    if ready == "after the coarse frames":
        monkeypatch.setattr(type(staged), "ready", property(lambda self: False))
    frames = staged.refine(cam, tolerance=1e-3)
    made = [next(frames)]
    if ready == "after the first coarse frame":
        staged.wait()  # from here on the full stage is ready
    made += list(frames)
    assert [(f.meta["stage"], f.reduction) for f in made] == stages and [f.index for f in made] == [0, 1, 2, 3]
    coarse = [s for s, _ in stages].count("coarse")
    figures = [f.figures() for f in made]
    for n in ("rms", "max"):
        errors = [f[f"relative_{n}_error"] for f in figures][coarse - 1:]  # from the last coarse frame on
        assert all(b < a for a, b in zip(errors, errors[1:])), (n, errors)
        for f, stage in zip(figures[:-1], stages):  # the full stage's previews
            assert stage[0] == "coarse" or 1 <= f[f"estimated_relative_{n}_error"] / f[f"relative_{n}_error"] <= 4, f
    direct = RayTracer(WaveletVolume.open(model_file)).render(cam, tolerance=1e-3)
    assert np.array_equal(made[-1].image, direct.image)


def test_a_small_staged_refinement_halves_the_error_from_the_coarse_frame_on(tmp_path):
    """An image too small to reduce (48^2) of a lod=True staged tracer ready after its coarse frame: the full stage's
    coarser details follow it only where they halve the error of the frame before, the coarse frame's included
    (docs/raytracing.md §9); the last frame the direct render."""
    for name in ("hydrogen", "marschner-lobb"):
        path = tmp_path / f"{name}.clw"
        model(name, n=32).save(path)
        staged, cam = RayTracer.open(path, lod=True), clwave.Camera(30, 20, size=48)
        frames = staged.refine(cam, tolerance=1e-2)
        made = [next(frames)]
        staged.wait()
        made += list(frames)
        assert made[0].meta["stage"] == "coarse" and len(made) >= 3 and {f.reduction for f in made} == {1}
        errors = [f.figures()["relative_rms_error"] for f in made]
        assert all(b <= a / 2 for a, b in zip(errors, errors[1:])), (name, errors)
        assert np.array_equal(made[-1].image, RayTracer(WaveletVolume.open(path)).render(cam, tolerance=1e-2).image)


@pytest.mark.parametrize("model_file", ["cubic"], indirect=True)  # the refinement is the same for both
def test_an_abandoned_staged_refinement_leaves_the_tracer_usable(model_file):
    """A viewer stops iterating when the view changes: during the coarse frames (the set-up goes on) and during the
    full stage's previews; the next view's frames still end at the direct render, bit for bit."""
    staged = RayTracer.open(model_file)
    frames = staged.refine(clwave.Camera(30, 20, size=128), tolerance=1e-3)
    assert next(frames).meta["stage"] == "coarse"
    frames.close()
    staged.wait()
    frames = staged.refine(clwave.Camera(50, 10, size=128), tolerance=1e-3)
    assert (next(frames).meta["stage"], staged.full.expansions) == ("full", 1)
    frames.close()
    cam = clwave.Camera(-20, 40, size=128)
    last = list(staged.refine(cam, tolerance=1e-3))[-1]
    assert staged.full.expansions == 1  # nothing set up again
    assert np.array_equal(last.image, RayTracer(WaveletVolume.open(model_file)).render(cam, tolerance=1e-3).image)


@pytest.mark.parametrize("model_file", ["cubic"], indirect=True)
def test_a_refinement_after_the_set_up_is_given_up_raises_abandoned(model_file):
    """``abandon()`` (a viewer stopping) before the set-up starts: ``refine`` yields the coarse frames, then raises
    ``Abandoned`` where the full stage's would begin, as does a coarse frame's final image; ``wait()`` gives None and
    ``render`` the coarse stage, the image another tracer's coarse stage gives."""
    camera = clwave.Camera(30, 20, size=64)
    staged = RayTracer.open(model_file)
    staged.abandon()
    frames = []
    with pytest.raises(Abandoned, match="given up"):
        for frame in staged.refine(camera, tolerance=1e-2):
            frames.append(frame)
    assert frames and all(f.meta["stage"] == "coarse" for f in frames)
    with pytest.raises(Abandoned, match="given up"):
        frames[0].final_image()
    assert staged.wait() is None and not staged.failed
    with pytest.raises(Abandoned, match="given up"):
        next(staged.refine(camera, tolerance=1e-2))  # set-up over: no coarse frame first
    result, other = staged.render(camera, tolerance=1e-2), RayTracer.open(model_file)
    expect = other.render(camera, tolerance=1e-2)  # its first image: the coarse stage's
    other.wait()  # its set-up, which that image started, not left running into the next test
    assert result.meta["stage"] == expect.meta["stage"] == "coarse" and np.array_equal(result.image, expect.image)


def test_a_set_up_given_up_stops_between_two_slabs_of_its_expansion(model_file, monkeypatch):
    """At exit (staged._abandon) the full stage's thread stops before the next slab of its expansion (the tracer's
    ``abandon``), leaving no full stage and no failure, so that the interpreter does not wait for the whole set-up;
    the model a caller holds (``whole=``, the viewer's) is left as it was, its mask read on."""
    expand = bricks._expand_slab
    for whole in (None, WaveletVolume.open(model_file)):
        staged, slabs = StagedTracer(RayTracer, model_file, whole=None if whole is None else lambda: whole), []

        def give_up_in_the_first(wv, gi, lay, slots, *args):
            slabs.append(int(slots[0]))  # each slab's first slot, once per group
            staged._abandon.set()  # as the interpreter's exit does
            return expand(wv, gi, lay, slots, *args)

        monkeypatch.setattr(bricks, "_expand_slab", give_up_in_the_first)
        staged.start()
        assert staged.wait() is None and staged._failure is None
        assert len(set(slabs)) == 1 and len(slabs) == len(staged.coarse.wv.groups), slabs  # its groups, no other slab
    assert whole.content_mask.box((0, 0, 0), (2, 2, 2)).shape == (2, 2, 2)


def test_a_tracer_of_chosen_details_refuses_others_in_one_line():
    wv = WaveletVolume.from_volume(smooth_volume(n=16), wavelet="cubic", levels=2).threshold(keep=0.2)
    for bad in ((3,), (), "coarse", (1.5,)):
        with pytest.raises(clwave.errors.InputError, match="lod=") as err:
            RayTracer(wv, lod=bad)
        assert "\n" not in str(err.value)
    tracer, cam = RayTracer(wv, lod=(2,)), clwave.Camera(20, 10, size=8)
    assert tracer.details == (2,) and tracer.render(cam, absorption=False).meta["detail"] == 2
    with pytest.raises(clwave.errors.InputError, match="holds details 2 only, not detail 0$"):
        tracer.render(cam, absorption=False, detail=0)
    # refine() ends at the finest detail such a tracer holds, bit for bit its render (its previews: that detail too)
    cam = clwave.Camera(20, 10, size=64)
    frames = list(tracer.refine(cam, absorption=False))
    assert [(f.detail, f.reduction) for f in frames] == [(2, 2), (2, 1)]
    assert np.array_equal(frames[-1].image, tracer.render(cam, absorption=False).image)


def resident_bytes() -> int:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


@pytest.mark.skipif(getattr(ctypes.CDLL(None), "malloc_trim", None) is None, reason="glibc's malloc_trim only")
def test_memory_freed_but_kept_by_the_c_library_goes_back_to_the_system():
    """glibc keeps freed chunks below a live one in its heap: 96 MiB of 48 KiB arrays freed but the last stay
    resident until ``return_freed`` (docs/raytracing.md §6)."""
    chunks = [np.ones(6144) for _ in range(2048)]  # 48 KiB each, below glibc's mmap threshold: from the heap
    last = chunks.pop()
    del chunks
    before = resident_bytes()
    assert memory.return_freed()
    assert before - resident_bytes() >= 64 * 2 ** 20 and last.sum() == 6144


def test_a_render_in_passes_returns_the_freed_memory_before_its_first_region(monkeypatch):
    """The set-up's freed memory goes back to the system before a render's regions are read back from the scratch
    file (on PoCL into host memory): the 1024^3 staged run's peak (benchmarks.md §13). Only the first render after
    the set-up gives it back: later renders reuse what the last one freed, and a trim each cost it (§6)."""
    tracer, calls = RayTracer(out_of_core_model(), device_memory="14MiB"), []
    tables = type(tracer.bricks).tables
    monkeypatch.setattr(passes, "return_freed", lambda: calls.append("freed"))
    monkeypatch.setattr(type(tracer.bricks), "tables", lambda *a: calls.append("region") or tables(*a))
    meta = tracer.render(clwave.Camera(30, 20, size=32), tolerance=1e-2).meta
    assert meta["passes"] > 1 and calls == ["freed"] + ["region"] * meta["passes"]
    calls.clear()
    meta = tracer.render(clwave.Camera(60, 10, size=32), tolerance=1e-2).meta
    assert calls == ["region"] * meta["passes"]


def line_energies(coefficients, prototypes, direction, h=1 / 6) -> tuple:
    """NumPy oracle of a field ``sum_k c_k prod over axes of f_axis(y_axis - k_axis)`` (``prototypes``: one closed
    form and its support (lo, hi) per axis, z y x): its energy by a midpoint sum over the support, and the energy of
    its line integrals along ``direction`` by midpoint sums over a plane across it and along each line."""
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    lo = np.array([p[1][0] for p in prototypes], float)
    hi = np.array([p[1][1] for p in prototypes], float) + np.array(coefficients.shape) - 1
    centre, radius = (lo + hi) / 2, np.linalg.norm(hi - lo) / 2

    def field(points):  # (..., 3), a slab of points at a time: sum_k c_k prod_a f_a(p_a - k_a), axis by axis
        flat, out = points.reshape(-1, 3), np.empty(points.shape[:-1]).reshape(-1)
        ni, nj, nk = coefficients.shape
        for lo_ in range(0, len(flat), 2 ** 14):
            p = flat[lo_:lo_ + 2 ** 14]
            fi, fj, fk = (f(p[:, a, None] - np.arange(n)) for a, ((f, _), n) in enumerate(zip(prototypes,
                                                                                           coefficients.shape)))
            # the last axis summed first, one matrix product (einsum over all three at once: 4/5 of the test's time)
            inner = (fk @ coefficients.reshape(ni * nj, nk).T).reshape(-1, ni, nj)
            out[lo_:lo_ + 2 ** 14] = np.einsum("pij,pi,pj->p", inner, fi, fj)
        return out.reshape(points.shape[:-1])

    axes = [np.arange(a + h / 2, b, h) for a, b in zip(lo, hi)]
    energy = float(np.sum(field(np.stack(np.meshgrid(*axes, indexing="ij"), -1)) ** 2)) * h ** 3
    e1 = np.cross(d, np.eye(3)[np.argmin(np.abs(d))])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d, e1)
    s = np.arange(-radius + h / 2, radius, h)
    u, v, t = np.meshgrid(s, s, s, indexing="ij")
    points = centre + u[..., None] * e1 + v[..., None] * e2 + t[..., None] * d
    projection = field(points).sum(axis=2) * h
    return energy, float(np.sum(projection ** 2)) * h ** 2


def test_the_approximations_field_energy_is_its_quadrature():
    """field_energy (a closed-form sum over the coefficients) against a midpoint sum of the cubic B-spline field
    itself, on random coefficients."""
    wav = clwave.model.bspline.SplineWavelet(4)
    c = np.random.default_rng(7).normal(0.5, 1.0, (3, 4, 2))
    energy, _ = line_energies(c, [(wav.phi, (0, 4))] * 3, (1, 0, 0))
    assert field_energy(c[None], 4) == pytest.approx(energy, rel=2e-3)


@pytest.mark.parametrize("azimuth, elevation", [(0, 0), (30, 20), (-70, 55)])
def test_an_xray_frame_holds_the_approximations_line_integral_energy(tmp_path, azimuth, elevation):
    """line_energy of the coarse stage's X-ray image (two channels, unequal spacing, 32^2) against midpoint sums of
    the approximation's B-spline field's line integrals along the view's direction in lattice units, channels
    summed: the energy the coarse frames' X-ray estimate takes from the frame (docs/raytracing.md §9)."""
    path = tmp_path / "two.clw"
    WaveletVolume.from_volume(smooth_volume(n=16, channels=2), wavelet="cubic", levels=2).save(path)
    staged, cam = RayTracer.open(path), clwave.Camera(azimuth, elevation, size=32)
    view = cam.view(staged.coarse.wv)
    image = staged.coarse.render(cam, tolerance=1e-4, absorption=False, detail=staged.coarse_detail).image
    grid = approximation_grid(WaveletVolume.open(path, approximation=True).groups[0])
    phi = clwave.model.bspline.SplineWavelet(4).phi
    direction = view.n[::-1] / staged._lattice
    oracle = sum(line_energies(c, [(phi, (0, 4))] * 3, direction, h=1 / 2)[1] for c in grid)
    assert line_energy(image, view, staged._lattice, staged.levels) == pytest.approx(oracle, rel=2e-3)


def test_a_white_detail_band_keeps_the_share_its_wavelets_line_integrals_keep():
    """detail_share: the largest over the seven coarsest-level types of a wavelet's line-integral energy over its
    energy (the quadrature oracle on one function), and nothing of a type whose wavelet lies along the ray;
    white_share of the approximation's B-splines (the clamped-off field's share in X-ray frames) the same."""
    wav = clwave.model.bspline.SplineWavelet(4)
    support = dict(a=(wav.phi, (0, 4)), d=(wav.psi, (0, 7)))
    direction = (0.3, -0.5, 0.81)
    shares = []
    for key in ("aad", "ada", "daa", "add", "dad", "dda", "ddd"):
        energy, projected = line_energies(np.ones((1, 1, 1)), [support[letter] for letter in key], direction)
        shares.append(projected / energy)
    assert detail_share(wav, direction) == pytest.approx(max(shares), rel=5e-3)
    energy, projected = line_energies(np.ones((1, 1, 1)), [support["a"]] * 3, direction)
    assert white_share(wav, direction, "aaa") == pytest.approx(projected / energy, rel=5e-3)
    energy, projected = line_energies(np.ones((1, 1, 1)), [support[letter] for letter in "daa"], (1, 0, 0))
    assert projected <= 1e-6 * energy  # psi along the ray: its vanishing moment


def test_a_finer_levels_white_band_keeps_half_the_coarsest_levels_share():
    """A level-(L - 1) wavelet is half as long in the coarsest lattice's units (psi(2y), phi(2y)), so a white band of
    it keeps half the share of the coarsest level's in the line integrals: the X-ray term weighs the finer levels'
    energy by half of detail_share (docs/raytracing.md §9).  The quadrature oracle on one function per type."""
    wav = clwave.model.bspline.SplineWavelet(4)
    support = dict(a=(lambda y: wav.phi(2 * y), (0, 2)), d=(lambda y: wav.psi(2 * y), (0, 3.5)))
    direction = (0.3, -0.5, 0.81)
    shares = []
    for key in ("aad", "ada", "daa", "add", "dad", "dda", "ddd"):
        energy, projected = line_energies(np.ones((1, 1, 1)), [support[letter] for letter in key], direction, h=1 / 12)
        shares.append(projected / energy)
    assert max(shares) == pytest.approx(detail_share(wav, direction) / 2, rel=5e-3)


class WarningTracer(RayTracer):
    """A ray tracer whose full stage's set-up (given ``abandon=``: the staged tracer's thread) warns."""

    def __init__(self, wv, **options):
        super().__init__(wv, **options)
        if options.get("abandon") is not None:
            clwave.errors.warn_outside(clwave.ClwaveWarning("the full stage's set-up warned"))


@pytest.mark.parametrize("model_file", ["cubic"], indirect=True)
def test_the_full_stages_set_up_warnings_reach_the_caller_once(model_file):
    """Warnings given on the set-up's thread went to Python's warnings from that thread, outside the caller's
    ``caught_warnings`` (a viewer's frame notes); they are given again, once, on the thread that takes the full
    stage."""
    staged = StagedTracer(WarningTracer, model_file)
    with clwave.errors.caught_warnings() as caught:
        assert staged.wait() is not None
    assert [str(w) for w in caught] == ["the full stage's set-up warned"]
    with clwave.errors.caught_warnings() as caught:  # once: not again
        staged.wait()
        staged.render(clwave.Camera(30, 20, size=16))
    assert caught == []
