"""Colour photo stacks rendered as their files mean them (docs/model.md §5): an image file's RGBA is straight colour and
alpha (Volume.photo), classified by its alpha (the photo preset), never taken as a classified model; the colour and
the alpha each scaled by its own range."""

import json

import imageio.v3 as iio
import numpy as np
import pytest
import tifffile

import clwave
from clwave import Camera, TransferFunction, Volume, WaveletVolume
from clwave.cli import main
from clwave.errors import InputError, NothingVisibleError

COLOUR = np.array([200.0, 120.0, 40.0])
OPACITY = 0.5  # the photo preset's, a voxel at alpha 1


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def cut_out(alpha=255):
    """An 8 x 16 x 16 RGBA photo stack, uint8: colour COLOUR on x < 8 with ``alpha``, white with alpha 0 on x >= 8 (a
    cut-out's background, which must not show)."""
    data = np.zeros((8, 16, 16, 4), np.uint8)
    data[..., :3] = 255
    data[:, :, :8, :3] = COLOUR
    data[:, :, :8, 3] = alpha
    return data


def slab_pixel(colour, extinction, length):
    """The emission-absorption pixel of a ray through a uniform slab: colour (1 - exp(-extinction length))."""
    return np.asarray(colour) * -np.expm1(-extinction * length)


def write_folder(folder, data, suffix=".png"):
    folder.mkdir()
    for z, image in enumerate(data):
        iio.imwrite(folder / f"s{z + 1}{suffix}", image)
    return folder


def test_image_files_colour_samples_are_photos_and_arrays_are_not(tmp_path):
    data = cut_out()
    tifffile.imwrite(tmp_path / "rgba.tif", data, photometric="rgb")
    np.save(tmp_path / "rgba.npy", data)
    tifffile.imwrite(tmp_path / "four.ome.tif", np.moveaxis(data, -1, 1), metadata={"axes": "ZCYX"})
    assert clwave.load(write_folder(tmp_path / "png", data)).photo
    assert clwave.load(write_folder(tmp_path / "rgb", data[..., :3], ".jpg")).photo
    assert clwave.load(tmp_path / "rgba.tif").photo
    assert not clwave.load(tmp_path / "rgba.npy").photo  # an array's 4 channels cannot be told apart
    assert not clwave.load(tmp_path / "four.ome.tif").photo  # channels, not colour samples
    assert not Volume(data).photo and Volume(data, photo=True).photo and not Volume(data[..., 0], photo=True).photo


def test_a_photo_model_keeps_it_through_its_file_and_its_classification_does_not(tmp_path):
    vol = Volume(cut_out(), photo=True)
    wv = WaveletVolume.from_volume(vol, levels=1)
    assert wv.photo and not wv.classified and wv.threshold(keep=0.5).photo and wv.reconstruct().photo
    wv.save(tmp_path / "p.clw")
    assert WaveletVolume.open(tmp_path / "p.clw").photo
    classified = TransferFunction.preset("photo").classify(vol)
    assert not classified.photo and WaveletVolume.from_volume(classified, levels=1).classified


def test_ray_tracing_a_photo_model_is_refused_naming_the_preset():
    wv = WaveletVolume.from_volume(Volume(cut_out(), photo=True), levels=1)
    with pytest.raises(InputError, match=r"photo's colour and alpha .* TransferFunction.preset\('photo'\)"):
        clwave.raytrace(wv, Camera(size=4))
    assert clwave.raytrace(wv, Camera(size=4), absorption=False).image.shape == (4, 4, 4)  # its line integrals


def test_the_photo_preset_gives_the_slab_pixel_and_the_transparent_part_nothing():
    """Seen along z (elevation 90), a ray through the coloured half crosses 8 voxels of extinction 0.5 a voxel times
    alpha: colour (1 - exp(-4 alpha)) exactly (an approximating B-spline model integrates its samples); a ray through
    the alpha-0 white half gives 0, where the 4 channels taken as classified emitted white."""
    for alpha in (255, 64):
        vol = Volume(cut_out(alpha), spacing=(2.0, 2.0, 2.0), photo=True)
        wv = WaveletVolume.from_volume(TransferFunction.preset("photo").classify(vol), levels=1)
        camera = Camera(0, 90, size=32, extent=32, target=(0, 0, 0))  # row 0 at the top, +v = -x: row 7 at x = -8.5
        image = clwave.raytrace(wv, camera, tolerance=1e-4, shading=False).image
        expected = slab_pixel(COLOUR / 255, OPACITY * alpha / 255 / 2.0, 16.0)
        np.testing.assert_allclose(image[7, 16, :3], expected, rtol=2e-3)
        np.testing.assert_allclose(image[7, 16, 3], -np.expm1(-OPACITY * alpha / 255 * 8), rtol=2e-3)
        np.testing.assert_allclose(image[24, 16], 0.0, atol=1e-6)


def test_the_command_line_classifies_a_photo_by_its_alpha(tmp_path, capsys):
    folder = write_folder(tmp_path / "png", cut_out())
    raw = tmp_path / "r.npy"
    code, out, err = run(capsys, "render", str(folder), "--method", "raytrace", "--azimuth", "0", "--elevation", "90",
                         "--extent", "32", "--size", "32", "--levels", "1", "--keep", "1", "--no-shading",
                         "--tolerance", "1e-4", "-o", str(tmp_path / "r.png"), "--raw", str(raw))
    assert code == 0, err
    assert "classified by its alpha (--tf photo" in out
    image = np.load(raw)  # framed on the content, the coloured half x < 0: row 16 at x = -8.5, row 2 at 5.5
    np.testing.assert_allclose(image[16, 16, :3], slab_pixel(COLOUR / 255, OPACITY, 8), rtol=2e-3)
    np.testing.assert_allclose(image[2, 16], 0.0, atol=1e-6)


def test_a_photo_clw_is_refused_for_shading_in_one_line(tmp_path, capsys):
    WaveletVolume.from_volume(Volume(cut_out(), photo=True), levels=1).save(tmp_path / "p.clw")
    code, _, err = run(capsys, "render", str(tmp_path / "p.clw"), "--method", "raytrace", "-o", str(tmp_path / "r.png"))
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "holds a photo's colour and alpha: compress the original volume with --tf photo" in err
    assert not (tmp_path / "r.png").exists()
    code, out, err = run(capsys, "info", str(tmp_path / "p.clw"))
    assert code == 0 and "a photo's colour and alpha, not classified" in out, err
    code, out, err = run(capsys, "info", str(tmp_path / "p.clw"), "--json")
    assert code == 0 and json.loads(out)["photo"] is True, err


@pytest.mark.parametrize("alpha_top", [1.0, 255.0, 65535.0])
def test_colour_and_alpha_are_each_scaled_by_their_own_range(rng, alpha_top):
    """Colour in 0 .. 255 beside alpha in 0 .. 1 (a mask), 0 .. 255 or 0 .. 65535: the alpha is divided by its own
    range, never by the colour's (a 0 .. 1 mask divided by 255 had made tissue 255 times too faint)."""
    colour = rng.integers(0, 256, (4, 5, 6, 3)).astype(np.float32)
    mask = (rng.random((4, 5, 6)) > 0.5).astype(np.float32)
    vol = Volume(np.concatenate([colour, (mask * alpha_top)[..., None]], -1))
    rgba = TransferFunction.preset("photo").classify(vol).data
    np.testing.assert_allclose(rgba[..., 3], OPACITY * mask, rtol=1e-6)
    np.testing.assert_allclose(rgba[..., :3], colour / 255 * (OPACITY * mask)[..., None], rtol=1e-6)


def test_an_alpha_beyond_16_bits_is_refused_naming_it():
    data = np.ones((4, 4, 4, 4), np.float32)
    data[..., 3] = 70000.0
    with pytest.raises(InputError, match=r"alpha values reach 70000"):
        TransferFunction.preset("photo").classify(Volume(data))


GEL, MUSCLE = (55, 85, 150), (150, 45, 40)  # a blue gel and muscle of about one luminance (0.33, 0.30)


def in_gel():
    """A 6 x 10 x 10 RGB stack, uint8: muscle in the middle 4 x 4 columns, blue gel around it."""
    data = np.empty((6, 10, 10, 3), np.uint8)
    data[...] = GEL
    data[:, 3:7, 3:7] = MUSCLE
    return data


def test_a_colour_key_makes_the_gel_transparent_and_keeps_the_tissue():
    vol = Volume(in_gel())
    for key in (GEL, "auto", (*GEL, 25.5)):
        alpha = TransferFunction.preset("photo").under(key=key).classify(vol).data[..., 3]
        np.testing.assert_array_equal(alpha[:, 3:7, 3:7], OPACITY)
        assert not alpha[:, :3].any() and not alpha[:, 7:].any()
    assert TransferFunction.preset("photo").under(key="auto").resolved(vol).key == (*map(float, GEL), None)


def test_a_colour_keys_edge_is_linear_from_the_tolerance_to_twice_it():
    """Greys at distances 0, 0.5, 1, 1.5, 2 and 3 tolerances (0.1 of the range) from the key black: opacities 0, 0, 0,
    half, all and all."""
    steps = np.array([0.0, 0.5, 1.0, 1.5, 2.0, 3.0]) * 0.1 / np.sqrt(3)  # a grey's distance from black: sqrt(3) g
    data = np.repeat(steps[:, None, None, None], 3, axis=3) * np.ones((6, 2, 2, 3))
    alpha = TransferFunction.preset("photo").under(key=(0, 0, 0)).classify(Volume(data)).data[:, 0, 0, 3]
    np.testing.assert_allclose(alpha, OPACITY * np.array([0, 0, 0, 0.5, 1, 1]), atol=1e-6)


def test_a_key_that_takes_all_the_opacity_is_named_as_the_cause(tmp_path, capsys):
    """A tolerance of 200 (of 255) around the gel's colour reaches the muscle too (its distance 151): the function
    alone gives every voxel opacity, so the refusal names the key and a smaller tolerance, not a window."""
    assert np.linalg.norm(np.subtract(GEL, MUSCLE)) < 200
    with pytest.raises(NothingVisibleError, match=r"the colour key \(55, 85, 150\), tolerance 200, makes transparent "
                                                  r"every voxel .*: give a smaller tolerance") as caught:
        TransferFunction.preset("photo").under(key=(*GEL, 200)).classify(Volume(in_gel()))
    assert "window" not in str(caught.value)
    folder = write_folder(tmp_path / "png", in_gel())
    code, _, err = run(capsys, "render", str(folder), "--tf", "photo", "--key", "55,85,150,200", "-o",
                       str(tmp_path / "r.png"))
    error = [line for line in err.splitlines() if line.startswith("clwave: error:")]
    assert code == 2 and len(error) == 1 and "give a smaller TOL (--key R,G,B,TOL) or another colour" in error[0], err


@pytest.mark.parametrize("argv, words", [
    (["--key", "auto"], "--key sets the colour key of a --tf preset: give --tf too"),
    (["--tf", "photo", "--key", "1,2"], "--key 1,2: give R,G,B or R,G,B,TOL"),
    (["--tf", "photo", "--key", "1,2,3,0"], "--key 1,2,3,0: give R,G,B or R,G,B,TOL"),
])
def test_a_bad_key_is_refused_in_one_line_before_reading(tmp_path, capsys, argv, words):
    code, _, err = run(capsys, "compress", str(tmp_path / "absent"), "-o", str(tmp_path / "m.clw"), *argv)
    assert code == 2 and len(err.strip().splitlines()) == 1 and words in err, err


def test_a_key_on_a_scalar_or_a_model_is_refused(tmp_path, capsys):
    np.save(tmp_path / "grey.npy", np.ones((4, 4, 4), np.float32))
    code, _, err = run(capsys, "compress", str(tmp_path / "grey.npy"), "--tf", "grey", "--key", "auto", "-o",
                       str(tmp_path / "m.clw"))
    assert code == 2 and "--key applies to a colour (RGB or RGBA) input; this one is scalar" in err, err
    scalar = WaveletVolume.from_volume(Volume(np.ones((4, 4, 4))), levels=1)
    with pytest.raises(InputError, match="colour key classifies a colour volume before the transform"):
        clwave.raytrace(scalar, Camera(size=4), transfer_function=TransferFunction.preset("grey").under(key="auto"))


def test_the_command_line_keys_a_gel_out(tmp_path, capsys):
    """Seen along z, the muscle's rays cross 6 voxels of 0.5: colour (1 - e^-3); the gel's give nothing."""
    folder = write_folder(tmp_path / "png", in_gel())
    raw = tmp_path / "r.npy"
    code, out, err = run(capsys, "render", str(folder), "--tf", "photo", "--key", "auto", "--method", "raytrace",
                         "--azimuth", "0", "--elevation", "90", "--extent", "10", "--size", "10",
                         "--levels", "1", "--keep", "1", "--no-shading", "--tolerance", "1e-4", "-o",
                         str(tmp_path / "r.png"), "--raw", str(raw))
    assert code == 0, err
    image = np.load(raw)
    np.testing.assert_allclose(image[5, 5, :3], slab_pixel(np.divide(MUSCLE, 255), OPACITY, 6), rtol=2e-3)
    np.testing.assert_allclose(image[0, 0], 0.0, atol=1e-6)


def test_a_key_survives_the_functions_description():
    tf = TransferFunction.preset("photo").under(key=(1, 2, 3, 4))
    assert TransferFunction.from_dict(tf.to_dict()) == tf and tf.key == (1.0, 2.0, 3.0, 4.0)
    assert TransferFunction.from_dict(tf.under(key="auto").to_dict()).key == "auto"


@pytest.mark.parametrize("suffix, kind", [(".png", "PNG"), (".jpg", "JPEG")])
def test_one_slice_is_refused_naming_its_folder(tmp_path, capsys, suffix, kind):
    folder = write_folder(tmp_path / "stack", in_gel(), suffix)
    for argv in (["info", str(folder / f"s1{suffix}")], ["render", str(folder / f"s1{suffix}"), "-o", "r.png"]):
        code, _, err = run(capsys, *argv)
        assert code == 2 and len(err.strip().splitlines()) == 1, err
        assert f"is one {kind} image; clwave reads a folder of {kind} slices as a stack: give its folder ({folder})" \
            in err


def test_the_viewer_offers_a_photo_model_x_ray_only():
    from clwave.view import view

    with view(WaveletVolume.from_volume(Volume(cut_out(), photo=True), levels=1), size=16) as v:
        assert v.server.hello()["modes"] == ["xray"]


def test_a_chunked_photo_is_classified_as_in_memory(rng):
    """A key "auto" and each channel's range found chunk by chunk: bit for bit the in-memory classification."""
    import dask.array as da

    data = np.concatenate([in_gel(), np.full((6, 10, 10, 1), 1, np.uint8)], -1).astype(np.float32)  # a 0/1 alpha
    data[:, 3:7, 3:7, 3] = rng.random((6, 4, 4))
    tf = TransferFunction.preset("photo").under(key="auto")
    whole = tf.classify(Volume(data)).data
    chunked = tf.classify(Volume(da.from_array(data, chunks=(3, 5, 5, 4)))).data.compute()
    np.testing.assert_array_equal(chunked, whole)
    assert not whole[:, :3].any() and whole[:, 3:7, 3:7, 3].max() > 0.4 * OPACITY  # the gel keyed, alpha 0 .. 1 kept
