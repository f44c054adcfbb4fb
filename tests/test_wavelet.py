"""WaveletVolume: perfect reconstruction, the continuous model, thresholding, LOD and .clw files."""

import warnings

import dask.array as da
import numpy as np
import pytest
import pywt

from clwave.model.bspline import SplineWavelet, bspline
from clwave.model.geometry import fine_to_world, support_centres
from clwave.errors import FileFormatError, InputError, OutputExistsError
from clwave.model.transform import band_code, band_key, band_layout, band_level
from clwave.model.volume import Volume
from clwave.model.wavelet import WaveletVolume

FAMILIES = ("haar", "linear", "quadratic", "cubic", "quintic")
SHAPE = (13, 10, 11)  # odd and unequal sizes
SPACING = (2.0, 1.0, 0.5)  # (dz, dy, dx): anisotropic


def fine_model(coeffs, start, order, fine_zyx):
    """Independent oracle: sum_i c_i N_j(x - i) over a fine coefficient array (float64)."""
    grids = [start[a] + np.arange(coeffs.shape[a]) for a in range(3)]
    w = [bspline(order, fine_zyx[:, a, None] - grids[a][None, :]) for a in range(3)]
    return np.einsum("ijkc,ni,nj,nk->nc", coeffs, *w)


def world_to_fine(points_xyz, shape, spacing, order):
    n, d = np.array(shape, float), np.array(spacing, float)
    return points_xyz[:, ::-1] / d + (n - 1) / 2 + order / 2


@pytest.fixture
def data(rng):
    return rng.random(SHAPE).astype(np.float32)


@pytest.mark.parametrize("family", FAMILIES)
def test_perfect_reconstruction(family, data):
    wv = WaveletVolume.from_volume(Volume(data, spacing=SPACING), wavelet=family, levels=2)
    rec = wv.reconstruct()
    assert rec.shape == SHAPE and rec.spacing == SPACING
    assert np.linalg.norm(rec.data - data) / np.linalg.norm(data) < 1e-5
    # the real-line synthesis agrees, and carries (almost) nothing outside the grid
    coeffs, start = wv.fine_coefficients()
    inside = tuple(slice(-s, -s + n) for s, n in zip(start, SHAPE))
    assert np.max(np.abs(coeffs[inside][..., 0] - data)) < 1e-5
    outside = coeffs.copy()
    outside[inside] = 0
    assert np.max(np.abs(outside)) < 1e-5


@pytest.mark.parametrize("family", FAMILIES)
def test_evaluate_equals_fine_level_spline(family, data, rng):
    wv = WaveletVolume.from_volume(Volume(data, spacing=SPACING), wavelet=family, levels=2)
    order = wv.groups[0].wavelet.order
    pts = rng.uniform(-1, 1, (300, 3)) * np.array([8.0, 7.0, 16.0])  # (x, y, z) inside and beyond
    fine = world_to_fine(pts, SHAPE, SPACING, order)
    expected = fine_model(data[..., None].astype(np.float64), (0, 0, 0), order, fine)
    assert np.max(np.abs(wv.evaluate(pts) - expected)) < 1e-5


@pytest.mark.filterwarnings("ignore:Level value of .* is too high")
@pytest.mark.parametrize("key", ["aad", "daa", "ada", "dda"])
def test_single_coefficient_matches_pywavelets_synthesis(key):
    """One level-2 detail coefficient: its closed-form basis equals the spline pywt synthesises.

    Asymmetric keys catch an axis swap (docs/model.md §4: letters are in array-axis order)."""
    shape = (40, 38, 44)  # larger than the level-2 psi support (28 voxels) on every axis
    wav = SplineWavelet(4)
    coeffs = pywt.wavedecn(np.zeros(shape), wav.pywt, mode="zero", level=2)
    band = coeffs[1][key]
    k = tuple(s // 2 for s in band.shape)
    band[k] = 1.0
    fine = pywt.waverecn(coeffs, wav.pywt, mode="zero")[: shape[0], : shape[1], : shape[2]]
    vol = Volume(np.zeros(shape), spacing=(1.5, 1.0, 0.75))
    only = WaveletVolume.from_volume(vol, "cubic", levels=2)  # then set that one coefficient
    g = only.groups[0]
    target = next(b for b in g.bands if b.level == 2 and b.key == key)
    values = np.zeros_like(g.values)
    values[0, target.start + np.ravel_multi_index(k, target.shape)] = 1.0
    g.values = values
    rng = np.random.default_rng(1)
    pts = rng.uniform(-12, 12, (400, 3))
    f = world_to_fine(pts, shape, vol.spacing, 4)
    expected = fine_model(fine[..., None], (0, 0, 0), 4, f)
    assert np.max(np.abs(only.evaluate(pts) - expected)) < 1e-6
    assert np.max(np.abs(expected)) > 1e-3  # the points do see the basis function


@pytest.mark.parametrize("family", ["cubic", "quintic"])
def test_interpolating_model_passes_through_samples(data, family):
    vol = Volume(data, spacing=SPACING)
    wv = WaveletVolume.from_volume(vol, family, levels=2, interpolate=True)
    idx = np.array([[i, j, k] for i in (0, 6, 12) for j in (0, 5, 9) for k in (0, 4, 10)], float)
    pts = vol.voxel_to_world(idx)
    got = wv.evaluate(pts)[:, 0]
    expected = data[tuple(idx.astype(int).T)]
    # float32 coefficients times the prefilter's gain: 1 / min of the sampling kernel's spectrum, 3 for cubic,
    # 120 / 16 = 7.5 for quintic
    tol = {"cubic": 1e-5, "quintic": 3e-5}[family]
    assert np.max(np.abs(got - expected)) < tol
    assert np.max(np.abs(wv.reconstruct().data - data)) < tol
    # the approximating model does not interpolate (it smooths)
    approx = WaveletVolume.from_volume(vol, family, levels=2)
    assert np.max(np.abs(approx.evaluate(pts)[:, 0] - expected)) > 1e-2
    # ... its value at a voxel centre is the weighted average of docs/model.md §1 (quintic: (1, 26, 66, 26, 1)/120)
    w = {"cubic": np.array([1, 4, 1]) / 6, "quintic": np.array([1, 26, 66, 26, 1]) / 120}[family]
    from scipy.ndimage import correlate
    smoothed = correlate(data.astype(np.float64), np.einsum("i,j,k->ijk", w, w, w), mode="constant")
    assert np.max(np.abs(approx.evaluate(pts)[:, 0] - smoothed[tuple(idx.astype(int).T)])) < 1e-5


@pytest.mark.parametrize("family", ["linear", "cubic", "quintic"])
def test_gradient_matches_finite_differences(family, rng):
    smooth = np.fromfunction(lambda z, y, x: np.sin(0.4 * x) * np.cos(0.3 * y) + 0.05 * z * z, SHAPE)
    wv = WaveletVolume.from_volume(Volume(smooth, spacing=SPACING), family, levels=2).threshold(keep=0.3)
    pts = rng.uniform(-1, 1, (60, 3)) * np.array([2.0, 3.0, 9.0]) + 0.0137
    h = 1e-5
    fd = np.stack([(wv.evaluate(pts + h * e) - wv.evaluate(pts - h * e)) / (2 * h) for e in np.eye(3)], -1)
    grad = wv.gradient(pts)
    assert grad.shape == (60, 1, 3)
    assert np.max(np.abs(grad - fd)) < 1e-4 * max(1.0, np.max(np.abs(fd)))


def test_real_line_synthesis_matches_pywavelets_on_thresholded_set(data):
    wv = WaveletVolume.from_volume(Volume(data), "cubic", levels=2).threshold(keep=0.2)
    coeffs, start = wv.fine_coefficients()
    inside = tuple(slice(-s, -s + n) for s, n in zip(start, SHAPE))
    assert np.max(np.abs(coeffs[inside][..., 0] - wv.reconstruct().data)) < 1e-5
    # and evaluate() equals the fine spline of the thresholded model everywhere, also beyond the grid
    pts = np.random.default_rng(3).uniform(-9, 9, (200, 3))
    expected = fine_model(coeffs, start, 4, world_to_fine(pts, SHAPE, (1, 1, 1), 4))
    assert np.max(np.abs(wv.evaluate(pts) - expected)) < 1e-5


@pytest.mark.parametrize("colour", ["cubic", "quintic"])
def test_mixed_orders_per_channel(rng, colour):
    rgba = rng.random(SHAPE + (4,)).astype(np.float32)
    wv = WaveletVolume.from_volume(Volume(rgba), [colour, colour, colour, "haar"], levels=2)
    assert wv.wavelets == (colour, colour, colour, "haar") and len(wv.groups) == 2
    assert np.max(np.abs(wv.reconstruct().data - rgba)) < 1e-5
    pts = rng.uniform(-4, 4, (50, 3))
    expected = fine_model(rgba[..., 3:].astype(np.float64), (0, 0, 0), 1, world_to_fine(pts, SHAPE, (1, 1, 1), 1))
    assert np.max(np.abs(wv.evaluate(pts)[:, 3:] - expected)) < 1e-5


def test_levels_zero_keeps_voxels(data):
    wv = WaveletVolume.from_volume(Volume(data), "cubic", levels=0).threshold(keep=0.3)
    assert wv.kept == round(0.3 * data.size)
    kept_values = np.sort(wv.groups[0].values[0])
    assert np.allclose(kept_values, np.sort(data.ravel())[-wv.kept:])  # the largest voxels


@pytest.mark.parametrize("keep", [0.001, 0.01, 0.05, 0.5, 1.0])
def test_threshold_keeps_exact_count_and_approximation_first(keep, rng):
    vol = Volume(rng.random((16, 18, 20)).astype(np.float32) ** 4)
    wv = WaveletVolume.from_volume(vol, "cubic", levels=2)
    th = wv.threshold(keep=keep)
    # keep=1: every (non-zero) coefficient, more than the voxels (the B-splines reach past the faces)
    n = np.count_nonzero(wv.groups[0].values.any(axis=0)) if keep == 1 else round(keep * vol.data.size)
    assert th.kept == n and abs(th.compression - (1 - n / vol.data.size)) < 1e-12
    g = th.groups[0]
    n_approx = g.bands[0].size
    in_approx = np.count_nonzero(g.positions < n_approx)
    assert in_approx == min(n, n_approx)
    if n > n_approx:  # the kept details are the largest |c| ||psi|| ones
        full = wv.groups[0]
        imp = wv.importance(full)[n_approx:]
        kept_min = th.importance(g)[n_approx:].min()
        assert np.count_nonzero(imp > kept_min) <= n - n_approx


def test_default_levels_capped_by_the_shortest_axis_and_said():
    from clwave.model.transform import default_levels

    assert default_levels((96, 96, 96)) == (3, None) and default_levels((8, 9, 10), levels=2) == (2, None)
    levels, note = default_levels((96, 4, 96, 3))
    assert levels == 1 and "--keep" not in note
    assert note.startswith("1 decomposition level instead of the default 3: the y axis of 4 voxels allows no more")
    levels, note = default_levels((96, 96, 3))
    assert levels == 0 and "x axis of 3 voxels" in note and "--keep drops voxels: give --keep 1" in note
    assert "--keep" not in default_levels((96, 96, 3), thresholded=False)[1]
    assert default_levels((1, 64, 64))[0] == 0  # an axis of one voxel: no level, not -1
    for shape in ((96, 96, 3), (96, 4, 96), (7, 16, 17)):  # the levels given are the most the model takes
        levels = default_levels(shape)[0]
        WaveletVolume.from_volume(np.ones(shape, np.float32), "haar", levels=levels)
        with pytest.raises(InputError):
            WaveletVolume.from_volume(np.ones(shape, np.float32), "haar", levels=levels + 1)


def test_default_levels_lowered_by_the_api_with_a_warning_as_by_the_command_line():
    """Without levels= the API takes the default (3) as the command line does: lowered where the shortest axis allows
    fewer, with a ClwaveWarning saying so, in memory and chunked; an explicit levels=3 is still refused."""
    import dask.array as da
    from clwave.errors import ClwaveWarning

    data = np.ones((8, 8, 8), np.float32)
    for volume in (Volume(data), Volume(da.from_array(data, chunks=4))):
        with pytest.warns(ClwaveWarning, match="^2 decomposition levels instead of the default 3: the z axis of 8 "):
            wv = WaveletVolume.from_volume(volume)
        assert wv.levels == 2
        with pytest.raises(InputError, match=r"levels=3 is not possible for shape \(8, 8, 8\)"):
            WaveletVolume.from_volume(volume, levels=3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a volume that allows the default: said nothing
        assert WaveletVolume.from_volume(np.ones((16, 16, 16), np.float32), "haar").levels == 3


def test_top_breaks_ties_at_the_cut_by_lowest_index(rng):
    from clwave.model.wavelet import _top

    importance = rng.integers(0, 5, 200).astype(np.float32)  # classes of 40 equal values
    for count in (0, 1, 39, 40, 41, 117, 199, 200, 250):
        oracle = np.sort(np.lexsort((np.arange(200), -importance))[:count])  # value descending, then index
        assert np.array_equal(_top(importance, count), oracle)


def test_band_ids_decode_to_their_bands():
    """band_level, band_code and band_key invert Band.id, one id or an array: each band of a layout read back, its
    key's letters against the code's bits as Band.code documents them (bit 0: 'd' along x, bit 2: along z)."""
    bands = band_layout(SplineWavelet(4), SHAPE, 3)
    ids = np.array([b.id for b in bands])
    assert len(set(ids)) == len(bands) == 1 + 7 * 3
    assert [(band_level(i), band_code(i), band_key(i)) for i in ids] == [(b.level, b.code, b.key) for b in bands]
    assert np.array_equal(band_level(ids), [b.level for b in bands])
    assert np.array_equal(band_code(ids), [b.code for b in bands])
    for code in range(8):
        assert [letter == "d" for letter in band_key(5 * 8 + code)] == [bool(code & 4), bool(code & 2), bool(code & 1)]


def test_threshold_by_value_and_ranked_order(rng):
    vol = Volume(rng.random((16, 16, 16, 2)).astype(np.float32))
    wv = WaveletVolume.from_volume(vol, "linear", levels=2)
    th = wv.threshold(threshold=0.05)
    imp = th.importance(th.groups[0])
    n_approx = th.groups[0].bands[0].size
    assert np.all(imp[n_approx:] > 0.05)
    assert np.count_nonzero(wv.importance(wv.groups[0])[n_approx:] > 0.05) == th.kept - n_approx
    table = th.ranked()  # by importance across all bands: the approximation band is not simply first
    assert np.all(np.diff(table.importance) <= 0) and set(band_level(table.band[:n_approx])) == {1, 2}
    assert table.values.shape == (th.kept, 2)
    per_band = th.bands()
    assert sum(len(idx) for _, idx, _ in per_band) == th.kept


def test_focus_keeps_more_detail_near_it(rng):
    vol = Volume(rng.random((32, 32, 32)).astype(np.float32))
    wv = WaveletVolume.from_volume(vol, "cubic", levels=2)
    centre = (-8.0, 4.0, 6.0)
    lod = wv.threshold(keep=0.3, focus=(centre, 5.0))
    g = lod.groups[0]
    n_approx = g.bands[0].size
    band_no, index = g.locate(g.positions[g.positions >= n_approx])
    fine = np.concatenate([support_centres(g.wavelet, band.key, band.level, index[band_no == b])
                           for b, band in enumerate(g.bands)])  # band by band: only the counts below matter
    centres = fine_to_world(fine, g.wavelet.order, *lod.frame)
    near = np.linalg.norm(centres - centre, axis=1) < 8
    far = np.linalg.norm(centres - (8.0, -4.0, -6.0), axis=1) < 8  # a mirrored ball of equal size
    assert near.sum() > 5 * max(far.sum(), 1)
    # the reconstruction is better near the focus than at the mirrored place
    err = np.abs(lod.reconstruct().data - vol.data)

    def around(point):  # a 9^3 block of voxels centred on a world point
        i, j, k = np.round(vol.world_to_voxel(np.array([point]))[0]).astype(int)
        return err[i - 4:i + 5, j - 4:j + 5, k - 4:k + 5].mean()

    assert around(centre) < 0.5 * around((8.0, -4.0, -6.0))


@pytest.mark.parametrize("centre, sigma, weight", [((0.0, 0.0, 0.0), 1e308, 1.0), ((1e308, 0.0, 0.0), 1.0, 0.0)])
def test_a_focus_at_the_ends_of_the_float_range_weighs_without_overflow(rng, centre, sigma, weight):
    """The focus weight exp(-d^2 / 2 sigma^2) at any finite sigma > 0 and centre: 1 where sigma dwarfs every
    distance, 0 where the centre is beyond them all; sigma^2 overflowed a Python float (an internal error of a
    .clw file's focus, harden20's fuzzing), and d^2 warned."""
    from clwave.model.wavelet import band_importance

    wv = WaveletVolume.from_volume(Volume(rng.random((8, 8, 8)).astype(np.float32)), "linear", levels=1)
    g = wv.groups[0]
    band = g.bands[1]
    values = g.values[:, g.band_slices()[1]]
    index = np.stack(np.unravel_index(np.arange(band.size), band.shape), axis=1)
    plain = band_importance(g.wavelet, band, values, index, None, wv.frame)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        focused = band_importance(g.wavelet, band, values, index, (centre, sigma), wv.frame)
    assert np.array_equal(focused, plain * np.float32(weight))


@pytest.mark.parametrize("channels, wavelet", [(1, "cubic"), (4, "cubic"), (1, "quintic")])
def test_clw_round_trip_is_exact_and_small(tmp_path, channels, wavelet, rng):
    shape = (48, 40, 44)
    z, y, x = np.meshgrid(*[np.linspace(-1, 1, n) for n in shape], indexing="ij")
    blob = np.exp(-4 * (x * x + 2 * y * y + 3 * z * z)) + 0.05 * rng.random(shape)
    data = np.stack([blob * (c + 1) for c in range(channels)], -1)
    vol = Volume(data.astype(np.float32), spacing=(1.2, 1.0, 0.8), origin=(1, 2, 3))
    wv = WaveletVolume.from_volume(vol, wavelet, levels=3,
                                   transfer_function={"points": [[0, 1, 1, 1, 0.5], [1, 1, 1, 1, 0.5]]})
    th = wv.threshold(keep=0.05, focus=((0.0, 0.0, 0.0), 20.0))
    path = th.save(tmp_path / "v.clw")
    assert path.stat().st_size <= 0.10 * vol.data.nbytes
    back = WaveletVolume.open(path)
    assert back.shape == th.shape and back.spacing == th.spacing and back.origin == th.origin
    assert back.levels == 3 and back.wavelets == th.wavelets and back.focus == th.focus
    assert back.transfer_function == th.transfer_function
    g0, g1 = th.groups[0], back.groups[0]
    assert np.array_equal(g0.positions, g1.positions) and np.array_equal(g0.values, g1.values)
    assert np.array_equal(th.ranked().index, back.ranked().index)
    assert np.array_equal(th.ranked().values, back.ranked().values)
    with pytest.raises(OutputExistsError):
        th.save(path)
    th.save(path, overwrite=True)


def test_clw_bad_files(tmp_path, data):
    wv = WaveletVolume.from_volume(Volume(data), "linear", levels=1)
    path = wv.save(tmp_path / "a.clw")
    raw = path.read_bytes()
    cut = tmp_path / "cut.clw"
    cut.write_bytes(raw[: len(raw) // 2])
    junk = tmp_path / "junk.clw"
    junk.write_bytes(b"not a zip at all")
    for bad in (cut, junk, tmp_path / "missing.clw"):
        with pytest.raises(FileFormatError) as err:
            WaveletVolume.open(bad)
        assert "\n" not in str(err.value)
    assert not list(tmp_path.glob("*.tmp"))


def test_bad_arguments(data):
    vol = Volume(data)
    with pytest.raises(InputError, match="from 0 to 2"):
        WaveletVolume.from_volume(vol, "cubic", levels=3)
    with pytest.raises(InputError, match="unknown wavelet"):
        WaveletVolume.from_volume(vol, "daubechies", levels=1)
    wv = WaveletVolume.from_volume(vol, "cubic", levels=1)
    for keep in (0, -0.1, 1.5, float("nan")):
        with pytest.raises(InputError, match="keep"):
            wv.threshold(keep=keep)
    with pytest.raises(InputError):
        wv.threshold()
    with pytest.raises(InputError, match="focus"):
        wv.threshold(keep=0.1, focus=((0, 0), 1.0))
    with pytest.raises(InputError, match="points"):
        wv.evaluate(np.zeros((4, 2)))


@pytest.mark.parametrize("wavelet", ["haar", "cubic"])
def test_zero_coefficients_are_never_kept_or_stored(tmp_path, wavelet):
    data = np.zeros((24, 20, 16), np.float32)
    data[6:14, 5:12, 4:10] = np.random.default_rng(1).random((8, 7, 6))  # an empty margin all round
    wv = WaveletVolume.from_volume(Volume(data), wavelet, levels=2)
    assert np.any(wv.groups[0].values == 0)  # the transform has zero coefficients
    for th in (wv.threshold(keep=0.5), wv.threshold(threshold=0.0)):
        assert np.all(np.any(th.groups[0].values != 0, axis=0))
    path = tmp_path / "m.clw"
    wv.save(path)  # the whole transform: its zeros are not stored either
    back = WaveletVolume.open(path)
    assert np.all(np.any(back.groups[0].values != 0, axis=0))
    assert back.kept == np.count_nonzero(np.any(wv.groups[0].values != 0, axis=0))
    assert np.array_equal(back.reconstruct().data, wv.reconstruct().data)
    # the source's content travels with the model: its non-zero voxels and their box
    assert np.array_equal(back.content_mask, data != 0) and np.array_equal(back.content_box(), wv.content_box())


@pytest.mark.parametrize("shape", [(5, 7, 13), (9, 4, 16), (3, 6, 1)])
def test_content_mask_boxes_and_blocks_equal_the_byte_mask(rng, shape):
    """The packed mask's boxes are the byte mask's (False beyond the volume), for boxes that cross every edge
    and bytes; blocks put at any x offset land as numpy assignment does."""
    from clwave.model.mask import ContentMask

    dense = rng.random(shape) < 0.4
    mask = ContentMask.of(dense)
    assert mask.bits.nbytes == shape[0] * shape[1] * -(-shape[2] // 8)
    padded = np.pad(dense, 9)  # voxel i at i + 9
    for _ in range(40):
        start = rng.integers(-9, np.array(shape) + 1)
        size = rng.integers(1, 9, 3)
        want = padded[tuple(slice(a + 9, a + 9 + n) for a, n in zip(start, size))]
        assert np.array_equal(mask.box(start, size), want)
    built = ContentMask(shape)
    for z, y, x in np.ndindex(2, 2, 3):  # blocks of uneven sizes that tile the volume
        lo = np.array([z, y, x]) * -(-np.array(shape) // [2, 2, 3])
        hi = np.minimum(lo + -(-np.array(shape) // [2, 2, 3]), shape)
        if np.all(hi > lo):
            built.put(lo, dense[tuple(slice(a, b) for a, b in zip(lo, hi))])
    assert np.array_equal(built.bits, mask.bits) and np.array_equal(np.asarray(built), dense)
    with pytest.raises(ValueError, match="outside the mask"):
        built.put((0, 0, shape[2] - 1), np.ones((1, 1, 2), bool))


def test_a_transfer_function_a_file_could_not_hold_is_refused_when_the_model_is_made():
    """A model stores its transfer function as its file's reader checks it (TransferFunction.stored): one point,
    or a dict without points, is refused by ``from_volume`` (in memory and chunked), not written into a file that
    no reader opens."""
    vol = Volume(np.ones((8, 8, 8), np.float32))
    for tf in ({"points": [[0, 1, 1, 1, 0.5]]}, {"window": [0, 1]}):
        for v in (vol, Volume(da.from_array(vol.data, chunks=4))):
            with pytest.raises(InputError):
                WaveletVolume.from_volume(v, "linear", levels=1, transfer_function=tf)
