"""The transfer function's opacity unit (docs/model.md §5): opacities per ``opacity_unit`` of length, one voxel (the
smallest spacing) by default, so a volume renders the same in µm or mm; the nearly-opaque warning; the brightfield
preset."""

import json
import math
import warnings

import numpy as np
import pytest

import clwave
from clwave.cli import main
from clwave.errors import ClwaveWarning, InputError, NearlyOpaqueWarning
from clwave.model.transfer import TransferFunction

SLAB = TransferFunction([(0.0, 1.0, 1.0, 1.0, 0.0), (1.0, 1.0, 1.0, 1.0, 0.1)])
N = 16


def _slab(spacing):
    return clwave.Volume(np.ones((N, N, N)), spacing=spacing)


def _alpha_down_an_axis(wv, **kw):
    """The image's opacity at its centre, the camera looking down an axis of the cube (N voxels deep)."""
    image = clwave.raytrace(wv, clwave.Camera(0, 0, size=8), tolerance=1e-4, shading=False, **kw).image
    return float(image[4, 4, 3])


@pytest.mark.parametrize("spacing, unit", [((1.0, 1.0, 1.0), None), ((0.5, 0.5, 0.5), None),
                                           ((1.0, 1.0, 1.0), 4.0), ((0.005, 0.005, 0.005), 0.02)])
def test_a_slab_transmits_exp_of_minus_opacity_times_voxels_crossed(spacing, unit):
    """A cube of N voxels, opacity 0.1 per opacity unit: the opacity down an axis is 1 - exp(-0.1 N s / unit), unit
    one voxel (s) by default, whatever the spacing; pre- and post-classification alike."""
    tf = SLAB.under(opacity_unit=unit)
    want = 1 - math.exp(-0.1 * N * spacing[0] / (spacing[0] if unit is None else unit))
    pre = clwave.WaveletVolume.from_volume(tf.classify(_slab(spacing)), wavelet="haar")
    post = clwave.WaveletVolume.from_volume(_slab(spacing), wavelet="haar")
    assert abs(_alpha_down_an_axis(pre) - want) <= 2e-4
    assert abs(_alpha_down_an_axis(post, transfer_function=tf) - want) <= 2e-4


def test_spacing_one_classifies_bit_for_bit_as_per_world_unit(rng):
    """On a volume of spacing 1 the opacity unit (one voxel) is 1: the classification is the points' opacity itself,
    as before the unit, bit for bit (np.interp, an independent evaluation)."""
    vol = clwave.Volume(rng.uniform(-0.2, 1.2, (5, 6, 7)))
    got = SLAB.classify(vol).data[..., 3]
    np.testing.assert_array_equal(got, np.interp(vol.data, [0.0, 1.0], [0.0, 0.1]).astype(np.float32))


def test_micrometres_and_millimetres_render_alike(rng):
    """One anisotropic volume, spacing in µm and in mm: the same images to float rounding, pre- and post-classified;
    with an opacity unit of 1 world unit (the old meaning) they differ."""
    data = rng.uniform(0, 1, (8, 12, 12))
    images = {}
    for name, spacing in (("um", (10.0, 5.0, 5.0)), ("mm", (0.01, 0.005, 0.005))):
        vol = clwave.Volume(data, spacing=spacing)
        tf = TransferFunction.preset("grey")
        cam = clwave.Camera(30, 20, size=10)
        pre = clwave.WaveletVolume.from_volume(tf.classify(vol), levels=1)
        post = clwave.WaveletVolume.from_volume(vol, levels=1)
        images[name] = [clwave.raytrace(pre, cam, shading=False).image,
                        clwave.raytrace(post, cam, shading=False, transfer_function=tf).image,
                        clwave.raytrace(post, cam, shading=False, transfer_function=tf.under(opacity_unit=1.0)).image]
    for um, mm in zip(images["um"][:2], images["mm"][:2]):
        assert um[..., 3].max() > 0.05
        np.testing.assert_allclose(um, mm, atol=2e-3)  # the tracer's tolerance, 1e-3, each
    assert np.abs(images["um"][2] - images["mm"][2]).max() > 0.1


def test_the_unit_is_recorded_and_old_descriptions_keep_their_meaning():
    tf = TransferFunction.preset("hydrogen", opacity_unit=0.25)
    assert TransferFunction.from_dict(json.loads(json.dumps(tf.to_dict()))) == tf
    vol = clwave.Volume(np.linspace(0, 1, 64).reshape(4, 4, 4), spacing=(2.0, 0.5, 1.0))
    assert TransferFunction.preset("hydrogen").resolved(vol).opacity_unit == 0.5
    assert tf.resolved(vol).opacity_unit == 0.25
    old = dict(tf.to_dict(), version=1)  # written before the unit: its opacities per world unit
    del old["opacity_unit"]
    assert TransferFunction.from_dict(old).opacity_unit == 1.0
    assert TransferFunction.from_dict({"points": SLAB.points.tolist()}).opacity_unit is None
    for bad in (0, -1.0, float("nan"), "mm", True):
        with pytest.raises(InputError, match="opacity unit"):
            SLAB.under(opacity_unit=bad)


def _warned(tf, vol):
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        tf.classify(vol)
    return [str(w.message) for w in seen if issubclass(w.category, ClwaveWarning)]


def _ct_head(n=48):
    """A CT-like head in HU: air, a skull of +1200, brain +40 with a fat lump and a calcification."""
    z, y, x = (np.mgrid[0:n, 0:n, 0:n] + 0.5) / n * 2 - 1
    r = np.sqrt((x / 0.8) ** 2 + (y / 0.95) ** 2 + (z / 0.9) ** 2)
    v = np.where(r < 0.95, 1200.0, -1000.0)
    v[r < 0.85] = 40.0
    v[(r < 0.85) & (np.hypot(x - 0.3, np.hypot(y, z)) < 0.2)] = -100.0
    v[(r < 0.85) & (np.hypot(x + 0.3, np.hypot(y - 0.2, z)) < 0.15)] = 400.0
    return v


def test_nearly_opaque_everywhere_is_warned(rng):
    """A window of 0 .. 1 on 16-bit data puts the box's faces past its top: with the hydrogen preset's 0.1 a voxel
    the box's thinnest side (64 voxels) has optical depth 6.4 >= 5, a solid box: warned, naming the window, the
    data's range and the fixes; so is ct-bone's HU window on the raw values (0.5 x 64 = 32), and an opacity unit far
    below the voxel (grey's auto window, the median voxel about 0.025 per unit, a unit of a hundredth of a voxel: 2.5
    a voxel).  Grey's own auto window is not (the faces' median 0.025 x 64 = 1.6)."""
    vol = clwave.Volume(rng.integers(1000, 60000, (64, 64, 64)).astype(np.uint16), spacing=(5.0, 5.0, 5.0))
    told = _warned(TransferFunction.preset("hydrogen"), vol)
    assert len(told) == 1 and "nearly opaque" in told[0] and "its window is 0 .. 1, the volume's values 10" in told[0]
    assert "6.4 or more across the box's thinnest side: a solid box" in told[0] and "opacity_unit=" in told[0]
    told = _warned(TransferFunction.preset("ct-bone"), vol)  # its values no HU either (no air): said first
    assert len(told) == 2 and "is for CT in Hounsfield units" in told[0], told
    assert "32 or more across the box's thinnest side" in told[1], told
    told = _warned(TransferFunction.preset("grey", opacity_unit=0.05), vol)
    assert len(told) == 1 and "or more across one voxel" in told[0], told
    assert not _warned(TransferFunction.preset("grey"), vol)


def test_nearly_transparent_everywhere_is_warned():
    """A constant opacity k a voxel over a 16 x 20 x 24 box: the longest ray along its axes has optical depth 24 k, so
    k = 0.01 (0.24, 79 % through) is warned naming the window and the fixes, by classify and by the check of a scalar
    kept for classifying while rendering (through a strided grid: the same, the volume uniform); k = 0.011 (0.264)
    is not."""
    vol = clwave.Volume(np.ones((16, 20, 24)), spacing=(3.0, 2.0, 2.0))
    for k, seen in ((0.01, True), (0.011, False)):
        tf = TransferFunction([(0, 1, 1, 1, k), (2, 1, 1, 1, k)], name="faint")
        told = _warned(tf, vol)
        assert bool(told) == seen, told
        with warnings.catch_warnings(record=True) as checked:
            warnings.simplefilter("always")
            tf.check_visible(vol)
        assert [str(w.message) for w in checked] == told
    assert len(told := _warned(TransferFunction([(0, 1, 1, 1, 0.01), (2, 1, 1, 1, 0.01)], name="faint"), vol)) == 1
    assert ("the transfer function faint makes this volume nearly transparent (no ray along the box's axes has an "
            "optical depth above 0.24: a faint or black picture); its window is 0 .. 2") in told[0]
    assert "a shorter opacity unit (now 2)" in told[0]


@pytest.mark.parametrize("preset, spacing", [("ct-bone", 0.5), ("ct-soft-tissue", 0.5), ("ct-soft-tissue", 1.0)])
def test_normal_presets_are_not_warned(preset, spacing):
    vol = clwave.Volume(_ct_head(), spacing=spacing)
    assert not _warned(TransferFunction.preset(preset), vol)


def test_hydrogen_and_mri_presets_are_not_warned(rng):
    assert not _warned(TransferFunction.preset("hydrogen"), clwave.phantom("hydrogen", n=48))
    head = _ct_head() + 1000 + rng.normal(0, 30, (48, 48, 48))  # an MRI-like head filling the box, noisy air
    assert not _warned(TransferFunction.preset("mri"), clwave.Volume(head, spacing=1.0))


def test_brightfield_colours_by_the_voxels_own_rgb():
    """A stained blob (purple, luminance 0.35) on a white background, 8-bit RGB: the white is transparent, the stain
    keeps its own colour at the preset's opacity of its luminance, 0 on the auto window's normalised axis (the
    stain's luminance its 0.5th percentile): 0.3 a voxel."""
    rgb = np.full((8, 8, 8, 3), 255, np.uint8)
    stain = np.array([150, 60, 190], np.uint8)
    rgb[2:6, 2:6, 2:6] = stain
    out = TransferFunction.preset("brightfield").classify(clwave.Volume(rgb, spacing=0.5))
    assert np.all(out.data[0, 0, 0] == 0)
    alpha = 0.3 / 0.5  # per voxel, a voxel 0.5 long
    np.testing.assert_allclose(out.data[3, 3, 3], [*(stain / 255 * alpha), alpha], rtol=1e-6)


def test_command_line_opacity_unit(tmp_path, capsys):
    """--opacity-unit sets the unit of --tf (recorded in the model); a bad one is refused in one line."""
    out = tmp_path / "a.clw"
    assert main(["compress", "phantom:hydrogen:16", "--levels", "1", "--tf", "hydrogen", "--opacity-unit", "2",
                 "-o", str(out)]) == 0
    wv = clwave.WaveletVolume.open(out)
    assert wv.transfer_function["opacity_unit"] == 2.0
    assert "nearly transparent" in capsys.readouterr().err  # half as dense on 16 voxels: the densest ray 0.24
    assert main(["compress", "phantom:hydrogen:16", "--tf", "hydrogen", "--opacity-unit", "-1", "-o",
                 str(tmp_path / "b.clw")]) == 2
    err = capsys.readouterr().err
    assert "--opacity-unit -1 must be a length > 0" in err and len(err.strip().splitlines()) == 1
    assert main(["compress", "phantom:hydrogen:16", "--opacity-unit", "2", "-o", str(tmp_path / "c.clw")]) == 2
    assert "give --tf too" in capsys.readouterr().err


def test_a_files_opacity_unit_stays_under_another_window(tmp_path):
    from clwave.model.tf_file import named_transfer_function

    path = tmp_path / "mine.json"
    path.write_text(json.dumps(SLAB.under(opacity_unit=0.5).to_dict()))
    assert named_transfer_function(str(path), window=(0.0, 2.0)).opacity_unit == 0.5
    assert named_transfer_function("grey", window=(0.0, 2.0)).opacity_unit is None


def _rendered_warnings(render):
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        render()
    return [str(w.message) for w in seen if issubclass(w.category, NearlyOpaqueWarning)]


def test_rendering_through_a_transfer_function_warns_where_it_is_nearly_opaque(rng):
    """A scalar model classified while rendering is warned as its volume's classification is: ct-bone's HU window on
    raw 16-bit values (1000 .. 60000) gives the box's faces its top opacity, 0.5 a voxel, so across the box's 16
    voxels an optical depth of 8 >= 5, a solid box; the line names the input's values.  Once per function a tracer
    (a second render of it says nothing), and through clwave.raytrace; grey's own auto window is not warned."""
    data = rng.integers(1000, 60000, (N, N, N)).astype(np.uint16)
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), levels=1)
    tracer, cam = clwave.RayTracer(wv), clwave.Camera(30, 20, size=8)
    bone = TransferFunction.preset("ct-bone")
    told = _rendered_warnings(lambda: [tracer.render(cam, tolerance=1e-2, transfer_function=bone) for _ in range(2)])
    assert len(told) == 1 and "ct-bone makes this model nearly opaque (half its faces' voxels have an optical depth " \
                              "of 8 or more across the box's thinnest side: a solid box); its window is -1000 .. " \
                              f"2000, the input's values {data.min():.4g} .. {data.max():.4g}" in told[0], told
    assert not _rendered_warnings(lambda: tracer.render(cam, tolerance=1e-2, transfer_function=bone))
    assert not _rendered_warnings(lambda: tracer.render(cam, tolerance=1e-2,
                                                        transfer_function=TransferFunction.preset("grey")))
    told = _rendered_warnings(lambda: clwave.raytrace(wv, cam, tolerance=1e-2, transfer_function=bone))
    assert len(told) == 1 and "nearly opaque" in told[0]


def test_the_command_line_says_nearly_opaque_once(tmp_path, capsys, rng):
    """`render --classify post` checks its volume before the transform and renders its model through the function:
    one line, not one of each; a scalar .clw rendered with --tf (no volume to check) is told by its render."""
    path, model = tmp_path / "raw.npy", tmp_path / "raw.clw"
    np.save(path, rng.integers(1000, 60000, (N, N, N)).astype(np.uint16))
    common = ["--method", "raytrace", "--tolerance", "1e-2", "--size", "8", "--force"]
    assert main(["render", str(path), "--tf", "ct-bone", "--classify", "post", "--levels", "1", "-o",
                 str(tmp_path / "a.png"), *common]) == 0
    err = capsys.readouterr().err
    assert err.count("nearly opaque") == 1 and "makes this volume nearly opaque" in err, err
    assert main(["compress", str(path), "--levels", "1", "-o", str(model)]) == 0
    capsys.readouterr()
    assert main(["render", str(model), "--tf", "ct-bone", "-o", str(tmp_path / "b.png"), *common]) == 0
    err = capsys.readouterr().err
    assert err.count("nearly opaque") == 1 and "makes this model nearly opaque" in err and "--tf-window" in err, err
