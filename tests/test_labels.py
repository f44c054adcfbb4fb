"""Label maps (segmentations), as a neuroimaging user renders them (trial22, docs/model.md §5): a Haar model and a
categorical transfer function show exactly the labels each ray meets; a label map given a wavelet of higher order
is warned of, a CT or MRI is not; the command line takes a transfer function's points from a file."""

import json
import warnings

import nibabel as nib
import numpy as np
import pytest

import clwave
from clwave.errors import ClwaveWarning, InputError
from clwave.model.labels import looks_like_labels
from clwave.model.tf_file import read_transfer_function
from test_classify import ct_phantom
from test_cli import run

SHOWN = {1: (1.0, 0.0, 0.0, 0.4), 3: (0.0, 0.0, 1.0, 0.7)}  # labels 0, 2, 4 and 5 hidden


def label_map(shape=(6, 8, 8), block=2, seed=3):
    """Cubes of ``block`` voxels of labels 0 .. 5 at random: every boundary between labels."""
    rng = np.random.default_rng(seed)
    cubes = rng.integers(0, 6, tuple(n // block for n in shape))
    return np.kron(cubes, np.ones((block,) * 3, int)).astype(np.uint8)


def test_a_categorical_function_steps_at_the_halves_between_labels():
    tf = clwave.TransferFunction.labels(SHOWN)
    rgb, alpha = tf([0, 0.6, 1, 1.4, 1.6, 2, 2.4, 2.6, 3, 3.4, 3.6, 5])
    assert alpha.tolist() == [0, 0.4, 0.4, 0.4, 0, 0, 0, 0.7, 0.7, 0.7, 0, 0]
    assert rgb[2].tolist() == [1, 0, 0] and rgb[8].tolist() == [0, 0, 1]
    adjacent = clwave.TransferFunction.labels({1: (1, 0, 0, 1), 2: (0, 1, 0, 2)})  # one step from 1's row to 2's
    assert adjacent([1.4, 1.6])[1].tolist() == [1, 2]


@pytest.mark.parametrize("bad, words", [({}, "at least one label"), ({1.5: (1, 0, 0, 1)}, "1.5 is not a whole"),
                                        ({1: (1, 0, 0)}, "must be 4 numbers"), ({1: (2, 0, 0, 1)}, "outside [0, 1]")])
def test_a_categorical_function_refuses_what_is_no_label_colour(bad, words):
    with pytest.raises(InputError, match=words.replace("[", r"\[")):
        clwave.TransferFunction.labels(bad)


def test_haar_and_a_categorical_function_show_exactly_the_labels_each_ray_meets():
    """Looking down z (orthographic), a pixel's ray crosses one column of voxels: a Haar model's values there are
    its labels, so its opacity is 1 - exp(-sum of the shown labels' opacities x dz) (a closed form), red where the
    column holds label 1, blue where it holds 3, never green, and nothing where it holds neither.  A cubic model of
    every coefficient shows labels that are not there (every boundary 0 | 5 passes through 1 and 3)."""
    labels = label_map()
    vol = clwave.Volume(labels, spacing=(1.5, 1.0, 1.0))
    cam = clwave.Camera(azimuth=0, elevation=90, size=40, target=(0, 0, 0), extent=10.0)
    view = cam.view(vol)
    index = vol.world_to_voxel(view.pixel_centres().reshape(-1, 3))  # (i, j, k) of each pixel's column
    inside = np.all((index[:, 1:] > -0.5) & (index[:, 1:] < np.array(labels.shape[1:]) - 0.5), axis=1)
    clear = np.all(np.abs(index[:, 1:] - np.rint(index[:, 1:])) < 0.45, axis=1)  # not on a cell's edge
    j, k = np.rint(index[:, 1:]).astype(int).clip(0, 7).T
    columns = labels[:, j, k].T  # each pixel's labels along its ray
    depth = {label: (columns == label).sum(axis=1) * 1.5 for label in SHOWN}
    alpha = 1 - np.exp(-sum(SHOWN[label][3] * depth[label] for label in SHOWN))
    tf = clwave.TransferFunction.labels(SHOWN)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ClwaveWarning)  # the cubic model's label warning, and Haar's no shading
        images = {wav: clwave.raytrace(clwave.WaveletVolume.from_volume(vol, wavelet=wav, levels=1).threshold(keep=1.0),
                                       cam, transfer_function=tf, tolerance=1e-4).image.reshape(-1, 4)
                  for wav in ("haar", "cubic")}
    image, sure = images["haar"], inside & clear
    assert sure.sum() > 600 and (sure & (alpha == 0)).sum() > 40
    np.testing.assert_allclose(image[sure, 3], np.where(inside, alpha, 0)[sure], atol=1e-3)
    assert np.all((image[sure, 0] > 1e-3) == (depth[1][sure] > 0))
    assert np.all((image[sure, 2] > 1e-3) == (depth[3][sure] > 0))
    assert np.abs(image[:, 1]).max() < 1e-6
    false = sure & (alpha == 0) & (images["cubic"][:, 3] > 0.05)
    assert false.sum() > 10  # what the recipe avoids


def _nifti(path, data, intent=None):
    image = nib.Nifti1Image(data, np.eye(4))
    if intent:
        image.header.set_intent(intent)
    nib.save(image, path)
    return path


def test_a_label_map_given_a_wavelet_above_haar_is_warned_of_once(tmp_path):
    path = _nifti(tmp_path / "seg.nii.gz", label_map((24, 24, 24), 8))
    vol = clwave.load(path)
    assert vol.labels
    with pytest.warns(ClwaveWarning, match="looks like a label map.*cubic wavelet .order 4.*wavelet='haar'") as seen:
        clwave.WaveletVolume.from_volume(vol, levels=1)
    assert sum("label map" in str(w.message) for w in seen) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error", ClwaveWarning)
        clwave.WaveletVolume.from_volume(vol, wavelet="haar", levels=1)  # no warning
    # float labels are not told from their values, but NIFTI_INTENT_LABEL says so
    floats = _nifti(tmp_path / "float.nii.gz", label_map((24, 24, 24), 8).astype(np.float32))
    assert not clwave.load(floats).labels
    intent = _nifti(tmp_path / "intent.nii.gz", label_map((24, 24, 24), 8).astype(np.float32), "label")
    assert clwave.load(intent).labels


#: FreeSurfer's lookup table as its aseg and aparc+aseg use it: subcortical structures in 0 .. 255, cortical parcels
#: at 1000 + n (left) and 2000 + n (right); some 110 labels, numbered sparsely
ASEG = [0, 2, 4, 5, 7, 8, 10, 11, 12, 13, 14, 15, 16, 17, 18, 24, 26, 28, 30, 31, 41, 43, 44, 46, 47, 49, 50, 51, 52,
        53, 54, 58, 60, 62, 63, 72, 77, 80, 85, 251, 252, 253, 254, 255]
APARC_ASEG = ASEG[:-5] + [side + n for side in (1000, 2000) for n in range(1, 36) if n != 4]


def atlas_map(table, shape=(48, 48, 48), block=6, seed=5):
    """Cubes of ``block`` voxels, each a label of ``table`` at random (every label at least once), inside a shell of
    background (0) one cube thick."""
    rng = np.random.default_rng(seed)
    cells = tuple(n // block - 2 for n in shape)
    picks = np.concatenate([table, rng.choice(table, np.prod(cells) - len(table))])
    rng.shuffle(picks)
    return np.pad(np.kron(picks.reshape(cells), np.ones((block,) * 3, int)), block)


@pytest.mark.parametrize("table, dtype", [(ASEG, np.uint8), (ASEG, np.int32), (APARC_ASEG, np.int32),
                                          (APARC_ASEG, np.uint16)])
def test_freesurfer_label_maps_numbered_sparsely_are_label_maps(table, dtype):
    """An aseg (44 labels up to 255) and an aparc+aseg (108 labels up to 2035; more than 64, sparse): label maps,
    and the model of one with a wavelet above Haar is warned of."""
    data = atlas_map(table).astype(dtype)
    assert len(np.unique(data)) == len(table) and looks_like_labels(data)
    with pytest.warns(ClwaveWarning, match="looks like a label map"):
        clwave.WaveletVolume.from_volume(clwave.Volume(data), levels=1)


def test_an_8_bit_mri_with_plateaus_is_no_label_map():
    """Hundreds of 8-bit intensities filling 0 .. 255 are an image's, however flat its regions: the MNI152 T1
    template at 8 bits, its white matter set to 110 as FreeSurfer's T1.mgz normalises it (85 % of its neighbours
    equal, as a label map's are); and so are they scaled by 4 or 16, numbered sparsely but in even steps."""
    from test_progressive_raytrace import NILEARN_T1, nilearn_file

    t1 = np.asarray(nib.load(nilearn_file(NILEARN_T1)).dataobj)
    white = np.asarray(nib.load(nilearn_file("mni_icbm152_wm_tal_nlin_sym_09a_converted.nii.gz")).dataobj) > 0.9
    data = np.rint(t1 / t1.max() * 255).astype(np.uint8)
    data[white] = 110
    assert len(np.unique(data)) > 100 and not looks_like_labels(data)
    assert not looks_like_labels(data.astype(np.uint16) * 4) and not looks_like_labels(data.astype(np.int16) * 16)


@pytest.mark.parametrize("make", [
    lambda: np.rint(clwave.phantom("hydrogen", 48).data * 255).astype(np.uint8),          # MRI-like, 8 bit
    lambda: np.rint(clwave.phantom("hydrogen", 48).data * 4095).astype(np.uint16),        # 12 bit
    lambda: np.rint(clwave.phantom("marschner-lobb", 48).data * 255).astype(np.uint8),
    lambda: np.rint(clwave.phantom("shepp-logan", 48).data * 255).astype(np.uint8),       # 6 values 0 .. 255
    lambda: np.rint(clwave.phantom("hydrogen", 64).data * 10).astype(np.uint8),           # 0 .. 10, smooth
    lambda: np.interp(clwave.phantom("shepp-logan", 48).data, [0, 0.1, 0.5, 1],
                      [-1000, 0, 60, 1200]).astype(np.int16),                                # CT in HU
    lambda: (np.interp(clwave.phantom("shepp-logan", 48).data, [0, 0.1, 0.5, 1],
                       [-1000, 0, 60, 1200]) + 1024).astype(np.uint16),                     # CT stored unsigned
    lambda: ct_phantom(24).data.astype(np.int16),
    lambda: np.random.default_rng(0).normal(100, 20, (32, 32, 32)).clip(0, 255).astype(np.uint8)])  # noise
def test_ct_and_mri_integer_volumes_are_no_label_maps(make):
    data = make()
    assert data.dtype.kind in "iu" and not looks_like_labels(data)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ClwaveWarning)
        clwave.WaveletVolume.from_volume(clwave.Volume(data), levels=1)


def test_the_command_line_warns_once_and_takes_a_categorical_function_from_a_file(tmp_path, capsys):
    seg = _nifti(tmp_path / "seg.nii.gz", label_map((24, 24, 24), 8))
    code, out, err = run(capsys, "compress", str(seg), "--levels", "1", "-o", str(tmp_path / "a.clw"))
    assert code == 0 and err.count("label map") == 1 and "give it --wavelet haar" in err, err
    (tmp_path / "seg.csv").write_text("# label map colours\nlabel,r,g,b,opacity\n1,1,0,0,0.4\n3,0,0,1,0.7\n")
    code, out, err = run(capsys, "compress", str(seg), "--levels", "1", "--tf", str(tmp_path / "seg.csv"), "-o",
                         str(tmp_path / "pre.clw"))  # classified first: its colours blurred, said once too
    assert code == 0 and err.count("label map") == 1 and "blurs and rings its colours" in err, err
    (tmp_path / "seg.json").write_text(json.dumps({"labels": {"1": [1, 0, 0, 0.4], "3": [0, 0, 1, 0.7]}}))
    expected = clwave.TransferFunction.labels(SHOWN).points
    for name in ("seg.csv", "seg.json"):
        target = tmp_path / f"{name}.clw"
        code, out, err = run(capsys, "compress", str(seg), "--levels", "1", "--wavelet", "haar", "--tf",
                             str(tmp_path / name), "--classify", "post", "-o", str(target))
        assert code == 0 and "label map" not in err, err
        np.testing.assert_array_equal(clwave.WaveletVolume.open(target).transfer_function["points"], expected)
    from clwave.view import as_model  # the viewer's tf= takes the files too
    model = as_model(clwave.load(seg), tf=str(tmp_path / "seg.csv"), wavelet="haar", levels=1, classify="post")
    np.testing.assert_array_equal(model.transfer_function["points"], expected)
    points = tmp_path / "points.csv"
    points.write_text("value,r,g,b,opacity\n0,0,0,0,0\n5,1,1,1,0.5\n")
    assert read_transfer_function(points) == clwave.TransferFunction([(0, 0, 0, 0, 0), (5, 1, 1, 1, 0.5)],
                                                                      name="points")
    dumped = tmp_path / "dumped.json"
    dumped.write_text(json.dumps(clwave.TransferFunction.preset("ct-bone").to_dict()))
    assert read_transfer_function(dumped) == clwave.TransferFunction.preset("ct-bone")


@pytest.mark.parametrize("name, text, words", [
    ("missing.csv", None, "missing.csv does not exist"),
    ("bad.json", "{not json", "bad.json: not JSON"),
    ("dict.json", '{"colours": 1}', 'dict.json: give a list of'),
    ("short.csv", "0,0,0,0\n1,1,1,1\n", "short.csv: row 1 '0,0,0,0' is not 5 numbers"),
    ("words.csv", "value,r,g,b,opacity\n0,0,0,0,x\n", "row 2 '0,0,0,0,x' is not 5 numbers"),
    ("half.csv", "label,r,g,b,opacity\n1.5,1,0,0,1\n", "label 1.5 is not a whole number"),
    ("bright.json", "[[0, 0, 0, 0, 0], [1, 2, 0, 0, 1]]", "colour [2.0, 0.0, 0.0] of point 1 is outside"),
    ("big.csv", "0,0,0,0,0\n" * 120000, "more than a function of points takes"),
    # found by refuzz22 (each was an internal error): a parser's recursion, integers past float, the csv field limit
    ("deep.json", "[" * 100000 + "]" * 100000, "deep.json: its JSON is nested deeper than"),
    ("huge.json", f"[[1{'0' * 400}, 0, 0, 0, 0], [1, 1, 1, 1, 1]]", "rows of 5 numbers (value, r, g, b, opacity) "
                                                                     "within float's range"),
    ("colour.json", f'{{"labels": {{"1": [1{"0" * 400}, 0, 0, 1]}}}}', "must be 4 numbers (r, g, b, opacity)"),
    ("window.json", f'{{"points": [[0, 0, 0, 0, 0], [1, 1, 1, 1, 1]], "window": [0, 1{"0" * 400}]}}',
     "window must be None, 'auto' or (lo, hi)"),
    ("field.csv", "0,0,0,0," + "1" * 200000 + "\n", "field.csv: not CSV (field larger than field limit")])
def test_a_bad_transfer_function_file_is_refused_in_one_line(tmp_path, capsys, name, text, words):
    if text is not None:
        (tmp_path / name).write_text(text)
    code, out, err = run(capsys, "compress", "phantom:hydrogen:16", "--tf", str(tmp_path / name), "-o",
                         str(tmp_path / "x.clw"))
    assert code == 2 and words in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "x.clw").exists()


# ---- dense maps of many labels, and the images they are told from: a corpus of both (docs/model.md §5)

def _voronoi(shape, n, seed, inside=None, by_place=False):
    """``n`` regions (the voxels nearest each of ``n`` seeds inside the mask ``inside``, 0 outside it), numbered
    1 .. n at random or, ``by_place``, in the seeds' raster order (as a segmentation tool numbers cells)."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(seed)
    inside = np.ones(shape, bool) if inside is None else inside
    where = np.argwhere(inside)
    seeds = where[rng.choice(len(where), n, replace=False)] + rng.random((n, 3)) - 0.5
    seeds = seeds[np.lexsort(seeds.T[::-1])] if by_place else seeds
    out = np.zeros(shape, np.uint16)
    out[inside] = (np.arange(n) if by_place else rng.permutation(n))[cKDTree(seeds).query(where)[1]] + 1
    return out


def _ball(n):
    z, y, x = np.indices((n, n, n)) - (n - 1) / 2
    return x ** 2 + y ** 2 + z ** 2 < (0.45 * n) ** 2


def _cells(n, count, radius, seed):
    """``count`` cells (balls of random radius in ``radius``, each voxel its nearest centre's) in a background of 0,
    numbered in raster order of their centres, as Cellpose or StarDist number theirs."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(seed)
    centres = rng.random((count, 3)) * n
    centres = centres[np.lexsort(centres.T[::-1])]
    distance, nearest = cKDTree(centres).query(np.argwhere(np.ones((n, n, n), bool)))
    return np.where(distance < rng.uniform(*radius, count)[nearest], nearest + 1, 0).reshape(n, n, n).astype(np.uint16)


def _shells(n, rings, sectors):
    """Nested shells, each cut into sectors about z: rings x sectors labels, numbered outwards."""
    z, y, x = np.indices((n, n, n)) - (n - 1) / 2
    ring = (np.sqrt(x ** 2 + y ** 2 + z ** 2) / (n / 2) * rings).astype(int)
    sector = ((np.arctan2(y, x) + np.pi) / (2 * np.pi) * sectors).astype(int) % sectors
    return np.where(ring < rings, ring * sectors + sector + 1, 0).astype(np.uint16)


def _mni(name, step=1):
    """An MNI152 template of the nilearn wheel as (z, y, x), every ``step``-th voxel."""
    from test_progressive_raytrace import nilearn_file

    return np.asarray(nib.load(nilearn_file(name)).dataobj)[::step, ::step, ::step].transpose(2, 1, 0)


def _parcellation(n, step, seed):
    """A cortical parcellation as Schaefer's, Brainnetome's or Harvard-Oxford's: the MNI152 grey matter (over 0.5),
    ``step`` mm a voxel, cut into ``n`` parcels around seeds in it, numbered left hemisphere first, back to front."""
    from scipy.spatial import cKDTree

    grey = _mni("mni_icbm152_gm_tal_nlin_sym_09a_converted.nii.gz", step) > 0.5
    where = np.argwhere(grey)
    seeds = where[np.random.default_rng(seed).choice(len(where), n, replace=False)]
    seeds = seeds[np.lexsort((seeds[:, 1], seeds[:, 2] > grey.shape[2] / 2))]  # left (x) first, then by y
    out = np.zeros(grey.shape, np.int16)
    out[grey] = cKDTree(seeds).query(where)[1] + 1
    return out


def _blocks(edge, block, dtype):
    """edge^3 cells of ``block`` voxels (z, y, x), labels 1 .. edge^3 at random: 39,304 for 34, above int16's 2^15."""
    cells = np.random.default_rng(6).permutation(edge ** 3).reshape(edge, edge, edge) + 1
    return np.kron(cells, np.ones(block, int)).astype(dtype)


def _quantised(values, top, dtype):
    values = np.asarray(values, float)
    return np.rint((values - values.min()) / (values.max() - values.min()) * top).astype(dtype)


def _blurred_regions(n, regions, sigma, top=255, dtype=np.uint8, noise=0.0):
    """A piecewise-constant phantom: regions of random intensities in a ball, their edges blurred (a Gaussian of
    ``sigma`` voxels) as a scanner's point spread blurs them, with Gaussian noise of ``noise`` (of the range)."""
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(regions)
    values = np.concatenate([[0], rng.uniform(0.2, 1, regions)])[_voronoi((n,) * 3, regions, 0, _ball(n))]
    return _quantised(gaussian_filter(values, sigma) + rng.normal(0, noise, values.shape), top, dtype)


def _microscopy(n, photons):
    """Cells of random brightness, blurred as a microscope's point spread blurs them, as photon counts (Poisson)
    over a camera's offset of 100: a uint16 fluorescence stack."""
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(photons)
    bright = np.concatenate([[0.05], rng.uniform(0.3, 1, 200)])[_cells(n, 200, (3, 8), 4)]
    return (rng.poisson(gaussian_filter(bright, 1.5) * photons) + 100).astype(np.uint16)


def _t1(bits, noise=0.0, step=1):
    """The MNI152 T1 template as an ``bits``-bit MRI, with Rician-like noise of ``noise`` (of its largest value)."""
    from test_progressive_raytrace import NILEARN_T1

    t1 = _mni(NILEARN_T1, step).astype(float)
    t1 = np.abs(t1 + np.random.default_rng(bits).normal(0, noise * t1.max(), t1.shape))
    return _quantised(t1, (1 << bits) - 1, np.uint8 if bits <= 8 else np.uint16)


MANY_LABELS = {  # more than 64 labels numbered densely, no NIfTI intent
    "voronoi 200 in a ball, at random": lambda: _voronoi((48,) * 3, 200, 1, _ball(48)),
    "voronoi 1000, by place": lambda: _voronoi((64,) * 3, 1000, 2, by_place=True),
    "grains 5000": lambda: _voronoi((96,) * 3, 5000, 3),
    "cells 300": lambda: _cells(64, 300, (3, 8), 4),
    "cells 3000, 2-5 voxels": lambda: _cells(96, 3000, (2, 5), 5),
    "shells 20 x 8 sectors": lambda: _shells(64, 20, 8),
    "cells 39304 uint16": lambda: _blocks(34, (2, 2, 8), np.uint16),
    "cells 39304 int32": lambda: _blocks(34, (2, 2, 8), np.int32),
    "parcels 200 1 mm": lambda: _parcellation(200, 1, 0),
    "parcels 400 2 mm": lambda: _parcellation(400, 2, 1),
    "parcels 96 2 mm": lambda: _parcellation(96, 2, 7),
    "parcels 300 3 mm": lambda: _parcellation(300, 3, 8)}
IMAGES = {  # integer images of more than 64 values (or masks), none a label map
    "T1 8 bit": lambda: _t1(8),
    "T1 8 bit, noise": lambda: _t1(8, 0.02),
    "T1 12 bit, noise": lambda: _t1(12, 0.02),
    "T1 8 bit 2 mm": lambda: _t1(8, step=2),
    "hydrogen 8 bit 128": lambda: _quantised(clwave.phantom("hydrogen", 128).data, 255, np.uint8),
    "hydrogen 12 bit": lambda: _quantised(clwave.phantom("hydrogen", 64).data, 4095, np.uint16),
    "marschner-lobb 8 bit": lambda: _quantised(clwave.phantom("marschner-lobb", 64).data, 255, np.uint8),
    "regions blurred 0.5": lambda: _blurred_regions(64, 100, 0.5),
    "regions blurred 1": lambda: _blurred_regions(64, 100, 1.0),
    "regions blurred 2": lambda: _blurred_regions(64, 30, 2.0),
    "regions blurred 1, 12 bit": lambda: _blurred_regions(64, 300, 1.0, 4095, np.uint16),
    "regions blurred 1, noise": lambda: _blurred_regions(64, 100, 1.0, noise=0.01),
    "microscopy 100 photons": lambda: _microscopy(64, 100),
    "microscopy 2000 photons": lambda: _microscopy(64, 2000),
    "CT uint16, noise": lambda: (np.interp(clwave.phantom("shepp-logan", 64).data, [0, 0.1, 0.5, 1],
                                           [-1000, 0, 60, 1200]) + 1024 + np.random.default_rng(0).normal(
                                           0, 20, (64,) * 3)).clip(0, 4095).astype(np.uint16),
    "mask 0/1": lambda: _ball(64).astype(np.uint8),
    "mask 0/255": lambda: _ball(64).astype(np.uint8) * 255}


@pytest.mark.parametrize("name", MANY_LABELS)
def test_a_dense_map_of_many_labels_is_a_label_map(name):
    """Parcellations (hundreds of parcels in the grey matter's ribbon, at 1 to 3 mm), cell masks (thousands, labels
    past int16's 2^15 in uint16 and int32), grains and shells: more than 64 labels, their boundaries abrupt."""
    data = MANY_LABELS[name]()
    assert len(np.unique(data)) > 65 and looks_like_labels(data)


@pytest.mark.parametrize("name", IMAGES)
def test_an_image_of_many_values_is_no_label_map(name):
    """MRI, CT, microscopy and phantoms of hundreds or thousands of values, their regions' edges blurred or noisy,
    and binary masks (a smooth 0 .. 1 step, no labels between), are no label maps."""
    data = IMAGES[name]()
    assert data.dtype.kind in "iu" and not looks_like_labels(data)


def test_labels_says_what_the_guess_cannot_know_both_ways(tmp_path, capsys):
    """``load(labels=)`` and ``--labels``/``--no-labels`` override the guess (and a NIfTI's intent): an image taken
    for labels (an 8-bit T1 upsampled by nearest neighbour, each value a 2-voxel run: abrupt boundaries) is given
    ``labels=False``, a map of few labels numbered thinly (no voxel pair equal) ``labels=True``."""
    upsampled = _t1(8, 0.02, step=4).repeat(2, 0).repeat(2, 1).repeat(2, 2)
    np.save(tmp_path / "t1.npy", upsampled)
    np.save(tmp_path / "thin.npy", np.indices((8, 8, 8)).sum(0).astype(np.uint8) % 2 * 7)  # 0 and 7 alternating
    intent = _nifti(tmp_path / "intent.nii.gz", label_map((24, 24, 24), 8).astype(np.float32), "label")
    assert looks_like_labels(upsampled) and clwave.load(tmp_path / "t1.npy").labels  # what the guess cannot tell
    assert not clwave.load(tmp_path / "t1.npy", labels=False).labels
    assert not clwave.load(tmp_path / "thin.npy").labels and clwave.load(tmp_path / "thin.npy", labels=True).labels
    assert not clwave.load(intent, labels=False).labels
    assert clwave.load(tmp_path / "t1.npy", chunks=8, labels=True).labels  # a chunked volume's values are not read
    with pytest.raises(InputError, match="labels='yes' must be True or False"):
        clwave.load(tmp_path / "t1.npy", labels="yes")
    for option, warned in (("--no-labels", 0), ("--labels", 1)):
        for path in ("t1.npy", "thin.npy"):
            code, out, err = run(capsys, "compress", str(tmp_path / path), "--levels", "1", option, "-o",
                                 str(tmp_path / "m.clw"), "--force")
            assert code == 0 and err.count("looks like a label map") == warned, err
    code, out, err = run(capsys, "info", str(tmp_path / "t1.npy"), "--no-labels", "--json")
    assert code == 0 and json.loads(out)["reading"]["labels"] is False
    code, out, err = run(capsys, "info", str(tmp_path / "t1.npy"), "--labels")
    assert code == 0 and "labels     a label map (--labels)" in out, out
    for option in ("--labels", "--no-labels"):
        code, out, err = run(capsys, "compress", "phantom:hydrogen:16", option, "-o", str(tmp_path / "p.clw"))
        assert code == 2 and f"{option} cannot apply to phantom:hydrogen:16" in err, err
        code, out, err = run(capsys, "render", str(tmp_path / "m.clw"), option, "-o", str(tmp_path / "p.png"))
        assert code == 2 and option in err and ".clw" in err and len(err.strip().splitlines()) == 1, err


def test_the_viewer_exports_labels_as_given(tmp_path):
    """A view's command line and Python keep ``--no-labels`` (a switch whose False is given) and ``--hu-to-mu``."""
    from clwave.cli import make_parser
    from clwave.view.export import Origin, Spec, command, python

    args = make_parser().parse_args(["view", str(tmp_path / "ct.nii"), "--no-labels", "--hu-to-mu", "--levels", "1"])
    origin = Origin.of_args(args)
    assert origin.get("labels") is False and origin.get("hu_to_mu") is True
    spec = Spec("xray", clwave.Camera(size=16, extent=10.0), window=(0.0, 1.0), levels=1)
    assert "--no-labels --hu-to-mu" in command(origin, spec) and "--labels " not in command(origin, spec)
    assert "hu_to_mu=True" in python(origin, spec) and "labels=False" in python(origin, spec)
