"""Level of detail of the ray tracer's B-spline field (clwave/raytrace/lod.py, docs/raytracing.md §8): the
bricks of each coarser detail against the closed-form model without the dropped details, clamped by a
brute-force occupancy; renders at a detail against the reference field on that model; detail chosen at render
time without a new expansion."""

from dataclasses import replace
from itertools import product

import numpy as np
import pytest

import clwave
from clwave import WaveletVolume
from clwave.device.constants import BLOCK, BRICK, SUPER
from clwave.model.bspline import SplineWavelet
from clwave.model.geometry import fine_to_world, world_to_fine
from clwave.model.mask import ContentMask
from clwave.model.transform import synthesize
from clwave.model.wavelet import ChannelGroup
from clwave.raytrace import bricks, lod, tracer as tracer_module
from clwave.raytrace.bounds import cell_blocks, content_cells
from clwave.raytrace.lod import Detail, any_blocks, occupancy
from clwave.raytrace.reference import Field, raytrace_reference, spline_field
from clwave.raytrace.tracer import RayTracer
from test_bricks import build, pool_field, smooth_rgba, smooth_volume

pytestmark = pytest.mark.opencl


def without_details(wv, level):
    """The model with the kept details of levels 1 .. ``level`` dropped (the closed-form coarser model)."""
    groups = []
    for g in wv.groups:
        keep = np.ones(g.kept, bool)
        for band, sl in zip(g.bands, g.band_slices()):
            if band.key != "aaa" and band.level <= level:
                keep[sl] = False
        groups.append(ChannelGroup(g.wavelet, g.channels, g.bands, g.all_positions()[keep], g.values[:, keep]))
    return WaveletVolume(wv.shape, wv.spacing, wv.origin, wv.levels, groups, wv.channels,
                         content_mask=wv.content_mask)


def brute_occupancy(mask, wavelet, level, start, shape):
    """Level-``level`` coefficient k is occupied where one of the 2^L fine B-splines at the centre of those
    inside its support (voxels o_L + 2^L k .. o_L + 2^L k + (2^L - 1) j, (2^L - 1) j + 1 of them) is a
    non-empty voxel: one coefficient at a time."""
    dense = np.asarray(mask)
    step, o = 2 ** level, wavelet.offset("a", level)
    inside = (step - 1) * wavelet.order + 1
    out = np.zeros(shape, bool)
    for idx in product(*(range(n) for n in shape)):
        lo = [o + step * (s + i) + (inside - step) // 2 for s, i in zip(start, idx)]
        hi = [a + step for a in lo]
        lo, hi = np.maximum(lo, 0), np.minimum(hi, dense.shape)
        out[idx] = np.all(hi > lo) and dense[tuple(slice(a, b) for a, b in zip(lo, hi))].any()
    return out


def coarse_fields(wv, detail):
    """The field at ``detail``, host side, per lattice level l >= detail its bricks may have: every group's
    level-l coefficients from the host's real-line synthesis of the bands above l, zeroed where not occupied
    (brute force), summed in closed form (alpha not clamped: docs/raytracing.md §8).  Returns
    ``field(points, level, derivative=False)`` (the values, or world gradients: reference.spline_field)."""
    fields = {}
    for level in range(detail, wv.levels + 1):
        parts = []
        for g in wv.groups:
            bands, dense = zip(*[(b, d) for b, d in zip(g.bands, g.dense_bands())
                                 if b.key == "aaa" or b.level > level])
            coeffs, start = synthesize(g.wavelet, bands, dense)
            if wv.content_mask is not None:
                coeffs = coeffs * brute_occupancy(wv.content_mask, g.wavelet, level, start, coeffs.shape[:3])[..., None]
            parts.append((g, coeffs, start))
        fields[level] = spline_field(wv, parts, level)
    return lambda points, level, derivative=False: fields[level](points, derivative)


def brick_slots(field, detail, x0) -> np.ndarray:
    """The slot of the brick holding each grid-0 fine point (z, y, x) at ``detail``, -1 for none."""
    b = np.floor(x0 / BRICK).astype(int) - field.origin
    inside = np.all((b >= 0) & (b < field.shape), axis=1)
    out = np.full(len(x0), -1)
    out[inside] = field.pages[detail][tuple(b[inside].T)]
    return out


def brick_levels(field, detail, x0) -> np.ndarray:
    """The lattice level of the brick holding each grid-0 fine point (z, y, x) at ``detail``, -1 for none."""
    slot = brick_slots(field, detail, x0)
    return np.where(slot >= 0, field.levels[slot], -1)


def detail_field(wv, tracer, detail, fields) -> Field:
    """The field a render at ``detail`` integrates, host side, for raytrace_reference (docs/raytracing.md §8): at
    each point ``fields`` (:func:`coarse_fields` of a detail at most ``detail``) at the level of the tracer's brick
    there, zero where no brick is, and zero on the blocks no content reaches (``content_cells``, itself tested against
    a census of the voxels) in the bricks clamped to content at the coarsest level."""
    f = tracer.bricks
    j0 = wv.groups[0].wavelet.order
    origin, shape = f.origin * BRICK, np.array(f.shape) * BRICK
    reached = None if wv.content_mask is None else cell_blocks(content_cells(wv, origin, shape))

    def field(points, derivative):
        x0 = world_to_fine(points, j0, wv.shape, wv.spacing, wv.origin)
        slot = brick_slots(f, detail, x0)
        where = np.where(slot >= 0, f.levels[slot], -1)
        if reached is not None:
            cut = np.flatnonzero((slot >= 0) & f.clamped[slot] & (where == wv.levels))
            block = (np.floor(x0[cut]).astype(int) - origin) // BLOCK
            where[cut[~reached[tuple(block.T)]]] = -1
        out = np.zeros((len(points), wv.channels, 3) if derivative else (len(points), wv.channels))
        for level in np.unique(where[where >= 0]):
            out[where == level] = fields(points[where == level], level, derivative)
        return out
    floor = tracer.grad_floor(q_bound=tracer.field_at(detail).q_bound)  # the float32 render's flat gradients
    # its pieces meet on the level-detail lattice (every coarser one lies on it), at brick faces and at the faces of
    # the blocks cut (BRICK is a multiple of BLOCK)
    lattice = (2.0 ** detail, wv.groups[0].wavelet.offset("a", detail) % 2 ** detail)
    return Field(field, (origin[::-1].astype(float), (origin + shape)[::-1].astype(float)), floor,
                 (lattice, (float(BRICK if reached is None else BLOCK), 0.0)))


def test_occupancy_equals_brute_force():
    wv = WaveletVolume.from_volume(smooth_volume(n=24, empty_corner=True), wavelet="cubic", levels=2)
    mask = np.asarray(wv.content_mask)
    mask[12:, 20:, :5] = False
    wv.content_mask = ContentMask.of(mask)
    for wavelet in (wv.groups[0].wavelet, SplineWavelet(2)):
        for level in (0, 1, 2, 3):
            start, shape = (-4, -3, -5), (16, 14, 17)
            assert np.array_equal(occupancy(wv.content_mask, wavelet, level, start, shape),
                                  brute_occupancy(wv.content_mask, wavelet, level, start, shape))


def test_any_blocks_equals_a_reduction_over_each_block():
    """lod.any_blocks (one axis at a time, the innermost read as words) against numpy's any over each block's three
    axes at once, for block sides that are a word (2, 4, 8) and that are not (1, 3, 16)."""
    rng = np.random.default_rng(8)
    for step in (1, 2, 3, 4, 8, 16):
        n = (3, 2, 5) if step == 16 else (4, 5, 3)
        for density in (0.002, 0.05):
            fine = rng.random(tuple(step * v for v in n)) < density
            want = fine.reshape(n[0], step, n[1], step, n[2], step).any(axis=(1, 3, 5))
            assert np.array_equal(any_blocks(fine, step), want)


@pytest.mark.parametrize("wavelet,levels,content", [("cubic", 3, True), ("cubic", 2, False), ("linear", 2, True),
                                                    (["cubic", "cubic", "cubic", "haar"], 2, True)])
def test_coarse_bricks_equal_the_model_without_the_finer_details(wavelet, levels, content):
    """Each coarser detail's bricks hold the model without the details of levels 1 .. L, clamped to the
    occupied coefficients of level L (docs/raytracing.md §8); full detail is the model itself."""
    wv = WaveletVolume.from_volume(smooth_volume(empty_corner=content), wavelet=wavelet, levels=levels)
    wv = wv.threshold(keep=0.1)
    if not content:
        wv.content_mask = None
    field = build(wv)
    j0 = wv.groups[0].wavelet.order
    x0 = np.random.default_rng(11).uniform(-20, 64, (250, 3))
    world = fine_to_world(x0, j0, wv.shape, wv.spacing, wv.origin)
    for detail in range(1, levels + 1):
        at = field.pages[detail][field.pages[detail] >= 0]
        assert np.all(field.levels[at] >= detail) and np.any(field.levels[at] == detail)
        fields, where = coarse_fields(wv, detail), brick_levels(field, detail, x0)
        ref = np.zeros((len(x0), wv.channels))
        for level in np.unique(where[where >= 0]):
            ref[where == level] = fields(world[where == level], level)
        assert np.abs(ref).max() > 0.1
        np.testing.assert_allclose(pool_field(wv, field, x0, detail=detail), ref, rtol=0,
                                   atol=2e-6 * np.abs(ref).max())
        if not content:  # nothing clamped: the colours of the closed-form model without the finer details
            np.testing.assert_allclose(ref[:, :3], without_details(wv, detail).evaluate(world)[:, :3], rtol=0,
                                       atol=1e-9 * np.abs(ref).max())


def test_single_precision_follows_double_at_every_detail():
    """float32 within rounding of float64 at every detail of an unmasked smooth model (a 3-9.5e-4 gap seen once in
    the eighth session did not reproduce in the ninth: docs/known-gaps.md §9): far below the tolerances rendered."""
    wv = WaveletVolume.from_volume(smooth_rgba(n=20), wavelet="cubic", levels=3)
    tr, cam = RayTracer(wv, lod=True), clwave.Camera(100, -35, size=12)
    for level in range(4):
        double = tr.render(cam, tolerance=1e-6, detail=level, precision="double").image
        single = tr.render(cam, tolerance=1e-5, detail=level).image
        assert np.abs(double).max() > 1 and np.abs(single - double).max() <= 3e-5 * np.abs(double).max()


@pytest.mark.parametrize("content", [False, True])
def test_coarse_details_render_the_oracle_of_the_coarser_model(content):
    """Renders at each coarser detail L against the NumPy oracle (reference.raytrace_reference) of the field
    docs/raytracing.md §8 defines for it, made on the host (:func:`detail_field`): X-ray within the tolerance, shaded
    within 1e-2 and 1e-3 (the oracle at 1e-5), segments 2^L cells long.  Two models whose coarse alpha dips below 0,
    so that alpha's clamp moves the oracle's image (measured: by 0.13-0.58 of 5.5 without a content mask, 0.06-2.2 of
    5.0 with one): three levels and no content mask (4^2), and two levels with one (the coarsest detail cuts the blocks
    no content reaches), seen through the 6^2 window of a 24^2 view around the ray where the light goes out between
    two samples of a 4-cell segment: without the normal's resolution test (docs/raytracing.md §2) that pixel is 7.8
    times the tolerance off at 1e-3."""
    wv = WaveletVolume.from_volume(smooth_rgba(n=40, empty_corner=content), wavelet="cubic", levels=2 if content else 3)
    wv = wv.threshold(keep=0.1)
    cam = clwave.Camera(25, 15, size=4)
    if content:
        view = clwave.Camera(25, 15, size=24).view(wv)  # rows 5..10, columns 14..19 of it
        cam = clwave.Camera(25, 15, size=6, target=view.target + view.pixel * (5 * view.u + 4 * view.v),
                            extent=6 * view.pixel)
    else:
        wv.content_mask = None
    tr = RayTracer(wv, lod=True)
    full, fields = tr.render(cam, tolerance=1e-3), coarse_fields(wv, 1)
    for level in range(1, wv.levels + 1):
        field = detail_field(wv, tr, level, fields)
        xray = raytrace_reference(wv, cam, tracer=tr, field=field, absorption=False)
        assert np.max(np.abs(tr.render(cam, tolerance=1e-3, detail=level, absorption=False).image - xray)) <= 1e-3
        oracle = raytrace_reference(wv, cam, tolerance=1e-5, tracer=tr, field=field)
        assert oracle.max() > 1
        for tol in (1e-2, 1e-3):
            coarse = tr.render(cam, tolerance=tol, detail=level)
            assert np.max(np.abs(coarse.image - oracle)) <= tol
        lattice = ("1", "2", "4", "8+")[level]
        assert coarse.meta["segments_by_lattice"][lattice] > 0.5 * coarse.meta["segments"]
        # (with a content mask, detail 1 blurs the content into empty space that full detail skips)
        assert coarse.meta["detail"] == level and (content or coarse.meta["segments"] < full.meta["segments"])
        assert np.max(np.abs(coarse.image - full.image)) > 1e-2  # the details dropped show
    # alpha's clamp matters: unclamped, the coarsest detail's alpha dips below 0 by 11-15 % of its largest value
    x0 = np.stack(np.meshgrid(*[np.linspace(0, 50, 24)] * 3, indexing="ij"), -1).reshape(-1, 3)
    alpha = coarse_fields(wv, wv.levels)(fine_to_world(x0, 4, wv.shape, wv.spacing, wv.origin),
                                                       wv.levels)[:, 3]
    assert alpha.min() < -0.05 * alpha.max()


def test_detail_changes_rebuild_nothing(monkeypatch):
    """After the set-up, renders at any detail (levels, screen-space errors, back to full) expand nothing; full
    detail is bit for bit the image of a tracer without the coarser details."""
    wv = WaveletVolume.from_volume(smooth_volume(n=40, empty_corner=True), wavelet="cubic", levels=2)
    wv = wv.threshold(keep=0.1)
    rgba = RayTracer(wv, lod=True)
    plain = RayTracer(wv).render(clwave.Camera(30, 20, size=16), tolerance=1e-3, absorption=False)

    def refuse(*args, **kwargs):
        raise AssertionError("a detail change expanded bricks")

    monkeypatch.setattr(tracer_module, "build", refuse)
    monkeypatch.setattr(tracer_module, "plan", refuse)
    monkeypatch.setattr(bricks, "build", refuse)
    cam = clwave.Camera(30, 20, size=16)
    images = {}
    for detail in (0, 2, 1, Detail(pixels=4.0), Detail(level=1, pixels=0.5), None):
        res = rgba.render(cam, tolerance=1e-3, absorption=False, detail=detail)
        images[repr(detail)] = res.image
        assert res.meta["detail_seconds"] < 1.0
    assert rgba.expansions == 1
    assert np.array_equal(images["None"], plain.image) and np.array_equal(images["0"], plain.image)
    assert not np.array_equal(images["2"], plain.image)


def test_screen_space_error_picks_levels_by_projected_cell_size():
    """Orthographic: the coarsest level whose cells project to at most the error in pixels, the same for every
    brick; perspective: finer near the eye than far from it."""
    wv = WaveletVolume.from_volume(smooth_volume(n=40), wavelet="cubic", levels=3).threshold(keep=0.1)
    wv.content_mask = None
    tr = RayTracer(wv, lod=True)
    cam = clwave.Camera(30, 20, size=10)  # the default framing: the volume's ~40 cells over 10 pixels
    pixel = cam.view(wv).pixel / max(wv.spacing)  # cells per pixel
    for pixels in (0.5, 1.0, 2.0):
        want = int(np.clip(np.floor(np.log2(pixels * pixel)), 0, 3))
        assert tr.render(cam, tolerance=1e-2, absorption=False, detail=Detail(pixels=pixels)).meta["detail"] == want
    near = clwave.Camera(30, 20, size=16, perspective=True, distance=30.0, fov=60)
    lo, hi = tr.render(near, tolerance=1e-2, absorption=False, detail=Detail(pixels=2.0)).meta["detail"]
    assert lo < hi


def test_bad_detail_is_one_clear_error():
    wv = WaveletVolume.from_volume(smooth_volume(n=24), wavelet="cubic", levels=2).threshold(keep=0.1)
    cam = clwave.Camera(30, 20, size=4)
    with pytest.raises(clwave.errors.InputError, match="lod=True"):
        RayTracer(wv).render(cam, absorption=False, detail=1)
    tr = RayTracer(wv, lod=True)
    for bad in (3, -1, 1.5, "coarse", Detail(pixels=0.0)):
        with pytest.raises(clwave.errors.InputError, match="detail|pixels"):
            tr.render(cam, absorption=False, detail=bad)


def test_empty_space_stays_empty_at_every_detail():
    """The haze bound (docs/raytracing.md §4) at every detail: at detail L the thresholded model, which rings
    far into the empty margin, is seen only by rays passing within the reach of an occupied level-L
    coefficient of the content, (2^L - 1) j + 2^L j cells (its refinement window and its support)."""
    from test_raytrace import classified_ball

    vol = classified_ball(n=64)
    thin = WaveletVolume.from_volume(vol, "cubic", levels=2).threshold(keep=0.05)
    margin = vol.voxel_to_world(np.argwhere(vol.content_mask() == 0)[::97])
    assert np.abs(thin.evaluate(margin)[:, 3]).max() > 1e-3  # the model rings in the empty margin
    cam = clwave.Camera(30, 20, size=48, extent=80.0)
    view = cam.view(thin)
    H, W = view.size
    r, c = np.mgrid[:H, :W]
    centres = (view.target + ((c + 0.5 - W / 2) * view.pixel)[..., None] * view.u
               + ((H / 2 - r - 0.5) * view.pixel)[..., None] * view.v).reshape(-1, 3)
    content = vol.voxel_to_world(np.argwhere(vol.content_mask()))
    off = content[None] - centres[:, None]  # (pixels, voxels, 3)
    distance = np.linalg.norm(off - (off @ view.n)[..., None] * view.n, axis=2).min(axis=1).reshape(H, W)
    tracer, j = RayTracer(thin, lod=True), 4
    for detail in range(3):
        image = tracer.render(cam, tolerance=1e-4, detail=detail).image
        far = distance > (2 ** detail - 1) * j + 2 ** detail * j
        assert 0.1 < far.mean() and np.all(image[far] == 0) and image.max() > 0.1


def test_coarser_details_render_in_passes_like_in_one():
    """Bricks beyond the device (docs/raytracing.md §6) at a coarser detail: the passes take that detail's
    slots, and the image is the one pass's, to rounding.  With the render's budget cut to 2 MiB after the set-up
    (which needs 12), a pass holds a brick or a few, so coarse segments (8 cells at detail 3, on a lattice 7 mod 8
    against the bricks' 16) cross the passes' boxes and resume there (``resume``): the segments, evaluations and
    early terminations are the one pass's, shaded and X-ray, and the images equal it within float rounding (1e-6 of
    the maximum; not bit for bit: a pass's first segment takes its first sample anew instead of the last segment's
    end sample, which rounds differently)."""
    from test_bricks import out_of_core_model

    wv = out_of_core_model()
    whole, parts = RayTracer(wv, lod=True), RayTracer(wv, lod=True, device_memory="14MiB")
    assert not parts.bricks.resident
    cam = clwave.Camera(30, 20, size=40)
    for detail in (0, 1, 3):
        a, b = whole.render(cam, tolerance=1e-3, detail=detail), parts.render(cam, tolerance=1e-3, detail=detail)
        assert b.meta["pool"] == "scratch file" and (b.meta["passes"] > 1 or detail > 0)
        assert a.meta["segments"] == b.meta["segments"] and a.meta["detail"] == detail
        assert np.max(np.abs(a.image - b.image)) <= 1e-6 * np.abs(a.image).max()
    parts.budget = replace(parts.budget, total=2 * 2 ** 20)
    for detail, absorption in product((1, 3), (True, False)):
        a = whole.render(cam, tolerance=1e-3, detail=detail, absorption=absorption)
        b = parts.render(cam, tolerance=1e-3, detail=detail, absorption=absorption)
        assert b.meta["passes"] >= 16 and a.meta["segments_by_lattice"][("1", "2", "4", "8+")[detail]] > 0
        for key in ("segments", "segments_by_lattice", "integrand_evaluations", "rays_terminated_early"):
            assert a.meta[key] == b.meta[key], key
        assert np.max(np.abs(a.image - b.image)) <= 1e-6 * np.abs(a.image).max()


def test_blocks_no_content_reaches_are_skipped_at_full_and_coarsest_detail():
    """docs/raytracing.md §8: at full detail (by the zeroed voxels) and at the coarsest (by the cut) a block bound
    is 0 where no non-empty voxel's B-spline reaches a cell of the block (content_cells, itself tested against a
    census of the voxels), and the bounds still hold the field where it reaches."""
    from test_raytrace import classified_ball

    wv = WaveletVolume.from_volume(classified_ball(n=32), "cubic", levels=2).threshold(keep=0.05)
    field = RayTracer(wv, lod=True).bricks
    origin, shape = field.origin * SUPER, np.array(field.shape) * SUPER
    reached = cell_blocks(content_cells(wv, origin * BLOCK, shape * BLOCK))
    x0 = np.random.default_rng(5).uniform(-8, 40, (400, 3))
    for detail in (0, 2):
        bound = field.bound_grid(field.pages[detail])
        assert not np.any(bound[~reached]) and np.any(bound[reached] > 0)
        values = np.abs(pool_field(wv, field, x0, detail=detail)).max(axis=1)
        block = np.floor(x0 / BLOCK).astype(int) - origin
        inside = np.all((block >= 0) & (block < shape), axis=1)
        live = np.zeros(len(x0), bool)
        live[inside] = reached[tuple(block[inside].T)]
        assert np.all(values[live] <= bound[tuple(block[live].T)] * (1 + 1e-6))


def test_coarse_segments_cross_brick_faces_on_one_lattice(monkeypatch):
    """docs/raytracing.md §3: at a coarser detail a segment crosses the face into a brick on the same coarse lattice
    (``lod.lattice_joins``): one segment a lattice cell, fewer than with a cut at every brick face; the X-ray image
    is the same to rounding (its segment integrals are exact, so a wrong coefficient would show).  Shaded, the joined
    segments are held to the oracle by test_coarse_details_render_the_oracle_of_the_coarser_model (this model)."""
    wv = WaveletVolume.from_volume(smooth_rgba(n=40, empty_corner=True), wavelet="cubic", levels=2).threshold(keep=0.1)
    cam = clwave.Camera(25, 15, size=24)
    joined = RayTracer(wv, lod=True)
    xray = {detail: joined.render(cam, tolerance=1e-6, detail=detail, absorption=False) for detail in (1, 2)}
    monkeypatch.setattr(lod, "lattice_joins", lambda field, pages: np.zeros(pages.shape, np.uint8))
    cut = RayTracer(wv, lod=True)
    for detail in (1, 2):
        a, b = xray[detail], cut.render(cam, tolerance=1e-6, detail=detail, absorption=False)
        assert a.meta["segments"] < 0.95 * b.meta["segments"]
        assert np.max(np.abs(a.image - b.image)) <= 1e-5 * np.abs(b.image).max()
