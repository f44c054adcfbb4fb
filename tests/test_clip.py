"""Clipping in the ray tracer (clwave.Clip, docs/raytracing.md §12): each ray's integral over its interval inside a
crop box and half-spaces, against the NumPy oracles cut in world coordinates and closed forms; bad input."""

import pickle
import re

import numpy as np
import pytest

import clwave
from clwave.device import programs
from clwave.errors import InputError
from clwave.raytrace.reference import classified_reference, raytrace_reference
from clwave.raytrace.regions import composite, slab_order, slabs
from clwave.raytrace.tracer import RayTracer
from test_cli import run
from test_raytrace import small_rgba  # noqa: F401  (a fixture: a random 5 x 6 x 7 RGBA model and its tracer)

PLANE = clwave.Clip(planes=[((0.3, 0.2, 0.0), (1.0, 0.5, 0.2))])
BOX_AND_PLANES = clwave.Clip(lo=(-2.0, -1.5, -1.0), hi=(3.0, 2.0, 1.5),
                             planes=[((0.3, 0.2, 0.0), (1.0, 0.5, 0.2)), ((0.0, 0.0, 0.5), (0.0, -0.3, -1.0))])
EVERYTHING = clwave.Clip(lo=(-1e3, -1e3, -1e3), hi=(1e3, 1e3, 1e3), planes=[((-1e3, 0.0, 0.0), (1.0, 0.0, 0.0))])


@pytest.mark.parametrize("clip", [PLANE, BOX_AND_PLANES], ids=["plane", "box and planes"])
@pytest.mark.parametrize("kw", [dict(absorption=False), dict(shading=False), dict()],
                         ids=["xray", "unshaded", "shaded"])
def test_clipped_render_equals_the_oracle_of_the_clipped_integral(small_rgba, clip, kw):  # noqa: F811
    """Orthographic and perspective (the eye inside the volume, in front of the plane), against raytrace_reference,
    whose intervals are cut in world coordinates; the clip changes the image."""
    wv, tracer = small_rgba
    for cam in (clwave.Camera(30, 20, size=(3, 4)),
                clwave.Camera(-40, 10, size=(3, 3), perspective=True, distance=1.0, fov=60)):
        ref = raytrace_reference(wv, cam, tolerance=1e-3, tracer=tracer, clip=clip, **kw)
        got = tracer.render(cam, tolerance=1e-3, clip=clip, **kw).image
        assert np.max(np.abs(got - ref)) <= 1e-5 * max(1.0, np.abs(ref).max())
        assert np.abs(ref).max() > 0.1
        assert np.abs(tracer.render(cam, tolerance=1e-3, **kw).image - got).max() > 0.1


@pytest.mark.parametrize("kw", [dict(), dict(absorption=False)])
def test_skipping_keeps_the_content_inside_the_clip(kw):
    """A faint volume with its content at one end, clipped so that rays start in the nearly empty superblocks that
    are crossed as one region: the skipping and the bound R are those of the clipped interval, as in the oracle."""
    rng = np.random.default_rng(4)
    data = rng.random((8, 8, 40, 4)) * 1e-10
    data[:, :, :8] = rng.random((8, 8, 8, 4)) * 0.5
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data.astype(np.float32)), wavelet="cubic", levels=1)
    tracer = RayTracer(wv)
    clip = clwave.Clip(planes=[((5.0, 0.0, 0.0), (-1.0, 0.1, 0.0)), ((-17.0, 0.0, 0.0), (1.0, 0.0, 0.2))])
    cam = clwave.Camera(0, 10, size=(3, 4), extent=8.0)  # rays along -x: from x = 5 through the faint part
    ref = raytrace_reference(wv, cam, tolerance=1e-3, tracer=tracer, clip=clip, **kw)
    got = tracer.render(cam, tolerance=1e-3, clip=clip, **kw)
    assert np.abs(ref).max() > 0.05 and got.meta["segments"] < tracer.render(cam, tolerance=1e-3, **kw).meta["segments"]
    assert np.max(np.abs(got.image - ref)) <= 1e-5 * np.abs(ref).max()


@pytest.mark.parametrize("field", ["bspline", "wavelet"])
def test_a_uniform_box_cut_by_a_plane_gives_the_chord_closed_forms(field):
    """A Haar box of q = 2, alpha = 0.5 over [-3, 3]^3, seen along -x, cut by the plane x + y = 1 (keeping x + y >= 1)
    and the crop box z <= 1.5: each ray's chord is L = 3 - max(-3, 1 - y) (0 where z > 1.5), its X-ray q L and its
    emission-absorption q / alpha (1 - e^{-alpha L})."""
    q, alpha = 2.0, 0.5
    data = np.stack([np.full((6, 6, 6), q)] * 3 + [np.full((6, 6, 6), alpha)], axis=-1).astype(np.float32)
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), wavelet="haar", levels=0)
    tracer = RayTracer(wv, field=field)
    clip = clwave.Clip(lo=(-10, -10, -10), hi=(10, 10, 1.5), planes=[((0.5, 0.5, 0.0), (1.0, 1.0, 0.0))])
    cam = clwave.Camera(0, 0, size=(7, 9), extent=8.0)
    view = cam.view(wv)
    H, W = view.size
    centres = view.target + ((np.arange(W) + 0.5 - W / 2)[None, :, None] * view.u
                             + (H / 2 - np.arange(H) - 0.5)[:, None, None] * view.v) * view.pixel
    y, z = centres[..., 1], centres[..., 2]
    inside = (np.abs(y) < 3) & (np.abs(z) < 3) & (z <= 1.5)
    chord = np.where(inside, np.clip(3 - np.maximum(-3, 1 - y), 0, None), 0.0)
    assert len(np.unique(chord[inside])) >= 4 and chord.max() < 6
    xray = tracer.render(cam, tolerance=1e-4, absorption=False, clip=clip).image[..., 0]
    assert np.abs(xray - q * chord).max() <= 1e-4
    shaded = tracer.render(cam, tolerance=1e-4, shading=False, clip=clip).image
    exact = 1 - np.exp(-alpha * chord)
    assert np.abs(shaded[..., 3] - exact).max() <= 1e-4
    assert np.abs(shaded[..., :3] - (q / alpha * exact)[..., None]).max() <= 1e-4


def test_a_clip_around_the_whole_volume_gives_the_unclipped_image_bit_for_bit(small_rgba):  # noqa: F811
    wv, tracer = small_rgba
    cam = clwave.Camera(30, 20, size=(5, 6))
    for kw in (dict(), dict(shading=False), dict(absorption=False)):
        assert np.array_equal(tracer.render(cam, clip=EVERYTHING, **kw).image, tracer.render(cam, **kw).image)


@pytest.fixture(scope="module")
def hydrogen():
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=20), wavelet="cubic", levels=2)
    return wv.threshold(keep=0.3), clwave.TransferFunction.preset("hydrogen")


def test_a_post_classified_render_is_clipped(hydrogen):
    """A scalar model through a transfer function at render time, half of it cut away: within the tolerance of the
    brute-force float64 oracle of the clipped integral, and the whole volume's box changes nothing."""
    wv, tf = hydrogen
    tracer = RayTracer(wv)
    cam = clwave.Camera(30, 20, size=8)
    clip = clwave.Clip(planes=[((0.0, 0.0, 0.0), (0.1, 0.2, 1.0))])
    ref = classified_reference(wv, cam, tf, tracer=tracer, clip=clip)
    got = tracer.render(cam, tolerance=1e-3, transfer_function=tf, clip=clip).image
    assert ref[..., 3].max() > 0.04
    assert np.abs(got - ref).max() <= 1e-3
    whole = tracer.render(cam, tolerance=1e-3, transfer_function=tf).image
    assert np.abs(whole - got).max() > 0.02
    assert np.array_equal(tracer.render(cam, tolerance=1e-3, transfer_function=tf, clip=EVERYTHING).image, whole)


def test_a_new_clip_rebuilds_nothing_and_progressive_frames_are_clipped(small_rgba, monkeypatch):  # noqa: F811
    """Renders with other clips take the same kernel build (the half-spaces are arguments, not defines) and no new
    set-up; progressive ray tracing clips every frame, its last frame the clipped render bit for bit."""
    wv, tracer = small_rgba
    cam = clwave.Camera(30, 20, size=64)  # frames on 32^2, then 64^2
    builds, build = [], programs.build
    monkeypatch.setattr(programs, "build", lambda cc, files, defines, *a: builds.append(dict(defines))
                        or build(cc, files, defines, *a))
    images = [tracer.render(cam, clip=clip).image for clip in (None, PLANE, BOX_AND_PLANES)]
    assert builds[0] == builds[1] == builds[2] and tracer.expansions == 1
    assert not np.array_equal(images[1], images[2])
    frames = list(clwave.progressive(wv, cam, method="raytrace", tracer=tracer, clip=PLANE))
    assert len(frames) > 1 and np.array_equal(frames[-1].image, images[1])
    assert np.array_equal(list(tracer.refine(cam, clip=PLANE))[-1].image, images[1])


def test_slabs_of_a_cluster_render_clip_alike():
    """The slabs a Dask cluster renders (docs/raytracing.md §7), each clipped, composited in ray order: within the
    tolerance of the whole clipped image, though the crop box keeps nothing of the first slab (not refused there)."""
    vol = clwave.phantom("hydrogen", n=40)
    wv = clwave.WaveletVolume.from_volume(clwave.TransferFunction.preset("hydrogen").classify(vol), wavelet="cubic",
                                          levels=2).threshold(keep=0.2)
    parts, whole = slabs(wv, 3), RayTracer(wv)
    tracers = [RayTracer(wv, region=r) for r in parts]
    clip = clwave.Clip(lo=(-100, -100, -5), hi=(100, 100, 100), planes=[((0, 0, 0), (0.3, -1, 0.2))])
    for cam, kw in ((clwave.Camera(30, 20, size=24), {}), (clwave.Camera(-60, 35, size=24), dict(absorption=False))):
        want = whole.render(cam, clip=clip, **kw).image
        images = [t.render(cam, tolerance=1e-3 / len(parts), clip=clip, **kw).image for t in tracers]
        got = composite([images[i] for i in slab_order(wv, parts, cam)], kw.get("absorption", True))
        assert np.abs(want).max() > 0.4 and not images[0].any()
        assert np.max(np.abs(got - want)) <= 1e-3 + np.abs(want).max() * 2.0 ** -23
        assert np.abs(whole.render(cam, **kw).image - want).max() > 0.4


@pytest.mark.parametrize("kw, message", [
    (dict(planes=[((1, 2, 3), (1, 0, 0)), ((1, 2, 3), (-1, 0, 0))]), "keeps nothing"),
    (dict(lo=(0, 0, 0), hi=(1, 1, 1), planes=[((2, 0, 0), (1, 0, 0))]), "keeps nothing"),
    (dict(lo=(0, 0, 0), hi=(1, 0, 1)), "must be below its hi"),
    (dict(lo=(0, 0, 0)), "needs both corners"),
    (dict(), "needs a box"),
    (dict(planes=[((0, 0, 0), (0, 0, 0))]), "normal .* must be a non-zero direction"),
    (dict(planes=[((0, 0, np.nan), (1, 0, 0))]), "must be finite numbers"),
    (dict(lo=(0, 0, 0), hi=(1, np.inf, 1)), "must be finite numbers"),
    (dict(lo=(0, 0, "1"), hi=(1, 1, 2)), "lo=.* must be 3 finite numbers"),
    (dict(planes=[((0, 0, 0), (1, 0, 0))] * 7), "at most 6 planes"),
    (dict(planes=((0, 0, 0), (1, 0, 0))), "plane 0 .* must be \\(point, normal\\)"),
    (dict(planes="x"), "must be a list of \\(point, normal\\)"),
    (dict(lo=np.zeros((3, 3)), hi=(1, 1, 1)), r"lo=array\(\[\[0., 0., 0.\], \[0., 0., 0.\], .* must be 3 finite"),
    (dict(planes=[np.eye(3)]), r"plane 0 array\(\[\[1., 0., 0.\], \[0., 1., 0.\], .* must be \(point, normal\)"),
])
def test_bad_clips_are_refused_in_one_line(kw, message):
    with pytest.raises(InputError, match=message) as caught:
        clwave.Clip(**kw)
    assert "\n" not in str(caught.value)


def test_planes_given_as_an_array_are_the_planes_given_as_a_list():
    rows = [((0, 0, 0), (1, 0, 0)), ((0, 1, 0), (0, -1, 1))]
    assert clwave.Clip(planes=np.array(rows, float)) == clwave.Clip(planes=rows)
    assert clwave.Clip(planes=[np.array(r, float) for r in rows]) == clwave.Clip(planes=rows)
    for bad in (np.zeros((2, 3)), [np.array(1.0)]):
        with pytest.raises(InputError, match="must be") as caught:
            clwave.Clip(planes=bad)
        assert "\n" not in str(caught.value)


def test_thin_but_real_clips_are_kept():
    """What keeps nothing is measured against the clip's own size: a micrometre slab is a region.  A clip pickles."""
    assert clwave.Clip(lo=(1e-6, 0, 0), hi=(2e-6, 1e-6, 1e-6)).keeps()
    assert clwave.Clip(planes=[((100, 0, 0), (1, 0, 0)), ((100 + 1e-6, 0, 0), (-1, 0, 0))]).keeps()
    assert PLANE.contains([(1.0, 0.2, 0.0), (-1.0, 0.2, 0.0)]).tolist() == [True, False]
    assert pickle.loads(pickle.dumps(BOX_AND_PLANES)) == BOX_AND_PLANES  # sent to a cluster's workers


@pytest.mark.parametrize("kw, kept", [
    (dict(lo=(-1e10, -1e10, 0), hi=(1e10, 1e10, 5)), True),  # a slab 5 thick: "everything between z = 0 and 5"
    (dict(lo=(-1e4, -1e4, 0), hi=(1e4, 1e4, 1e-5)), True),
    (dict(lo=(-1e10, -1e10, 0), hi=(1e10, 1e10, 5), planes=[((0, 0, 2.5), (0.0, 1e-3, 1.0))]), True),  # half of it
    (dict(lo=(-1e10, -1e10, 0), hi=(1e10, 1e10, 5), planes=[((0, 0, 6), (0, 0, 1))]), False),  # beyond its top
    (dict(lo=(-1e10, -1e10, 0), hi=(1e10, 1e10, 5), planes=[((0, 0, 2), (0, 0, 1)), ((0, 0, 2), (0, 0, -1))]), False),
])
def test_a_slab_box_keeps_what_its_thickness_holds(kw, kept):
    """Thinness is measured along each axis of the box, not against its widest side: a box 5 thick and 2e10 wide was
    refused as keeping nothing (its inscribed ball 2.5e-10 of its half-width)."""
    if kept:
        assert clwave.Clip(**kw).keeps()
    else:
        with pytest.raises(InputError, match="keeps nothing"):
            clwave.Clip(**kw)


def test_a_clip_that_misses_the_volume_or_is_not_a_clip_is_refused(small_rgba):  # noqa: F811
    wv, tracer = small_rgba
    cam = clwave.Camera(30, 20, size=4)
    with pytest.raises(InputError, match=r"keeps nothing of the volume's content, which lies within"):
        tracer.render(cam, clip=clwave.Clip(lo=(50, 50, 50), hi=(60, 60, 60)))
    with pytest.raises(InputError, match=r"clip=.* must be a clwave.Clip"):
        clwave.raytrace(wv, cam, clip=((0, 0, 0), (1, 1, 1)))


def test_cli_clips_render_and_progressive(tmp_path, capsys):
    """--clip-box and --clip-plane: the --raw image is the API's render with that Clip; progressive takes them too."""
    raw = tmp_path / "c.npy"
    args = ["phantom:hydrogen:16", "--levels", "1", "--keep", "1", "--method", "raytrace", "--xray", "--size", "12"]
    clip = ["--clip-box", "-100,-100,-100,100,100,0", "--clip-plane", "0,0,0,1,1,0"]
    code, out, err = run(capsys, "render", *args, *clip, "-o", str(tmp_path / "c.png"), "--raw", str(raw))
    assert code == 0, err
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", 16), wavelet="cubic", levels=1)
    want = RayTracer(wv, content_clamp=False).render(
        clwave.Camera(30, 20, size=12), absorption=False,
        clip=clwave.Clip(lo=(-100, -100, -100), hi=(100, 100, 0), planes=[((0, 0, 0), (1, 1, 0))])).image
    assert np.array_equal(np.load(raw), want)
    code, out, err = run(capsys, "progressive", *args, *clip, "-o", str(tmp_path / "p.gif"))
    assert code == 0 and (tmp_path / "p.gif").exists(), err


@pytest.mark.parametrize("extra, message", [
    (["--clip-box", "0,0,0,1,1,1"], "--clip-box is for --method raytrace"),
    (["--method", "raytrace", "--xray", "--clip-box", "0,0,0,1,1"], "--clip-box '0,0,0,1,1' must be 6 comma-separated"),
    (["--method", "raytrace", "--xray", "--clip-box", "0,0,0,1,nan,1"], "--clip-box 0,0,0,1,nan,1: .* finite"),
    (["--method", "raytrace", "--xray", "--clip-plane", "1,2,3,0,0,0"], "--clip-plane 1,2,3,0,0,0: .* non-zero"),
    (["--method", "raytrace", "--xray", "--clip-plane", "0,0,0,1,0,0", "--clip-plane", "0,0,0,-1,0,0"],
     "keeps nothing"),
    (["--method", "raytrace", "--xray", "--clip-box", "100,100,100,200,200,200"], "keeps nothing of the volume"),
])
def test_cli_bad_clips_are_one_line_exit_2(tmp_path, capsys, extra, message):
    out = tmp_path / "c.png"
    code, _, err = run(capsys, "render", "phantom:hydrogen:16", "--levels", "1", "--size", "8", *extra, "-o", str(out))
    lines = [line for line in err.splitlines() if line.startswith("clwave: error:")]
    assert code == 2 and len(lines) == 1 and not out.exists()
    assert re.search(message, lines[0]), lines[0]
