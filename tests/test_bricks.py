"""The brick-sparse multiresolution B-spline field (clwave/raytrace/bricks.py, docs/raytracing.md §3):
each brick's lattice coefficients against the model's closed-form field, the plan against a brute-force
census of the kept supports and the voxels, and the ray tracer's images against the dense fine-grid
path it replaced (tests/data/dense_reference.npz)."""

import dataclasses
import errno
import os
import re
import shutil
import tempfile
from itertools import product
from pathlib import Path

import numpy as np
import pytest

import clwave
from clwave import TransferFunction, WaveletVolume
from clwave.device.constants import BLOCK, BRICK, SUPER
from clwave.device.context import ComputeContext
from clwave.device.memory import device_budget
from clwave.errors import DeviceMemoryError, OutputError
from clwave.io.phantoms import phantom
from clwave.model.bspline import bspline, bspline_derivative
from clwave.model.geometry import band_lattice, fine_to_world
from clwave.raytrace import bricks, passes
from clwave.raytrace.reference import _content_field, raytrace_reference
from clwave.raytrace.tracer import RayTracer

pytestmark = pytest.mark.opencl


def spilled(spill: passes.Spill) -> np.ndarray:
    """The whole scratch file, (elements, 4) float32."""
    out = np.empty((spill.nbytes // 16, 4), np.float32)
    spill.read_into(0, out)
    return out


def pool_field(wv, field: bricks.BrickField, x0, derivative=False, detail=0):
    """The brick field at grid-0 fine points (N, 3) (z, y, x), from the pool read back: (N, 4), or the
    gradient (N, 4, 3) in fine units (z, y, x); the bricks of ``detail``."""
    pool = field.pool.get() if field.resident else spilled(field.spill)
    frames, boxes = field.frames, field.boxes
    pages = field.pages[detail]
    out = np.zeros((len(x0), 4, 3) if derivative else (len(x0), 4))
    for p, x in enumerate(x0):
        b = np.floor(x / BRICK).astype(int) - field.origin
        if np.any(b < 0) or np.any(b >= pages.shape) or pages[tuple(b)] < 0:
            continue
        slot = pages[tuple(b)]
        for gi, g in enumerate(wv.groups):
            j, frame, box = g.wavelet.order, frames[slot, gi], boxes[slot, gi]
            u = (x[::-1] - frame[:3]) * frame[3]  # lattice coordinates (x, y, z)
            coef = pool[box[3]:box[3] + np.prod(box[:3])].reshape(box[2], box[1], box[0], 4)
            k = np.floor(u).astype(int)[:, None] - np.arange(j)  # per axis (x, y, z) the j B-splines that reach
            assert np.all(k >= 0) and np.all(k < box[:3, None])  # the brick holds every B-spline that reaches
            near = coef[np.ix_(k[2], k[1], k[0])]  # (z, y, x, channel)
            w = [bspline(j, u[a] - k[a]) for a in range(3)]
            if derivative:
                dw = [bspline_derivative(j, u[a] - k[a]) * frame[3] for a in range(3)]
                for axis, (wz, wy, wx) in enumerate(((dw[2], w[1], w[0]), (w[2], dw[1], w[0]), (w[2], w[1], dw[0]))):
                    out[p, :, axis] += np.einsum("z,y,x,zyxc->c", wz, wy, wx, near)  # z, y, x
            else:
                out[p] += np.einsum("z,y,x,zyxc->c", w[2], w[1], w[0], near)
    return out


def build(wv, device_memory=None):
    cc = ComputeContext.get()
    return bricks.build(wv, cc, device_budget(cc, device_memory))


def smooth_volume(n=44, channels=4, empty_corner=False):
    """Smooth blobs (coarse bands carry them) with one sharp spike (fine detail only near it)."""
    z, y, x = np.mgrid[:n, :n, :n] / n
    base = 0.4 + 0.3 * np.sin(3 * x) * np.cos(2 * y) + 0.2 * z
    data = np.stack([base * (0.5 + 0.2 * c) for c in range(channels)], -1)
    data[n // 2, n // 3, 2 * n // 3] += 2.0
    if empty_corner:
        data[: n // 4, : n // 4, : n // 4] = 0
    return clwave.Volume(data.astype(np.float32), spacing=(1.0, 0.9, 1.1))


def smooth_rgba(n=44, empty_corner=False):
    """:func:`smooth_volume` as an RGBA model's input: colours of about 1, a faint alpha (rays see through)."""
    vol = smooth_volume(n=n, empty_corner=empty_corner)
    return clwave.Volume(vol.data * np.array([1.0, 0.8, 0.6, 0.05], np.float32), spacing=vol.spacing)


def census(wv):
    """Brute force: per brick (dict by index), the coarsest level holding every group exactly, from every kept
    coefficient's support box one by one."""
    j0 = wv.groups[0].wavelet.order
    level = {}
    for g in wv.groups:
        shift = (g.wavelet.order - j0) / 2.0
        _, index = g.locate(g.all_positions())
        band_no, _ = g.locate(g.all_positions())
        for i in range(g.kept):
            band = g.bands[band_no[i]]
            off, step, support = band_lattice(g.wavelet, band.key, band.level)
            lo = off - shift + step * index[i]
            hi = lo + step * support
            value = wv.levels if band.key == "aaa" else band.level - 1
            for b in product(*(range(int(np.floor(a / BRICK)), int(np.ceil(z / BRICK))) for a, z in zip(lo, hi))):
                level[b] = min(level.get(b, value), value)
    return level


@pytest.mark.parametrize("wavelet,levels", [("cubic", 3), ("linear", 2), ("quadratic", 2), ("haar", 2),
                                            (["cubic", "cubic", "cubic", "haar"], 2)])
def test_plan_equals_a_census_of_the_supports(wavelet, levels):
    wv = WaveletVolume.from_volume(smooth_volume(), wavelet=wavelet, levels=levels).threshold(keep=0.05)
    wv.content_mask = None
    p = bricks.plan(wv)
    expected = census(wv)
    got = {tuple(int(v) for v in b + p.origin): int(p.level[0][tuple(b)])
           for b in np.argwhere(p.level[0] != bricks.ABSENT)}
    assert got == expected
    assert len(set(got.values())) >= 2  # bricks of several levels side by side


def test_plan_clamps_bricks_where_empty_and_non_empty_voxels_meet():
    vol = smooth_volume(n=64, empty_corner=True)
    wv = WaveletVolume.from_volume(vol, wavelet="cubic", levels=2).threshold(keep=0.05)
    p = bricks.plan(wv)
    mask = np.pad(wv.content_mask, 64)  # voxel i at i + 64
    for b in np.argwhere(np.ones(p.level.shape[1:], bool)):
        first = (b + p.origin) * BRICK - 3 + 64  # voxels whose cubic B-splines reach the brick
        window = mask[tuple(slice(f, f + BRICK + 3) for f in first)]
        level, clamp = p.level[0][tuple(b)], p.clamp[0][tuple(b)]
        if not window.any():
            assert level == bricks.ABSENT
        elif not window.all():
            assert clamp and level == 0
        else:
            assert not clamp
    assert p.clamp[0].any() and (p.level[0] == bricks.ABSENT).any() and (p.level[0] > 0).any()


@pytest.mark.parametrize("wavelet,levels,content,keep", [("cubic", 3, False, 0.1), ("cubic", 2, True, 0.1),
                                                         ("linear", 2, True, 0.1), ("quadratic", 2, False, 0.1),
                                                         ("haar", 1, True, 0.1),
                                                         (["cubic", "cubic", "cubic", "haar"], 2, True, 0.1),
                                                         ("cubic", 2, True, None)])  # every coefficient stored
def test_brick_field_equals_the_model_at_random_points(wavelet, levels, content, keep):
    """Values and gradients, on bricks of every level, against the closed-form wavelet sum (with the content
    known: the host synthesis with empty voxels' fine coefficients zeroed, docs/raytracing.md §4); the bands'
    boxes come from kept coefficients scattered on the device, or from a model that stores every one."""
    vol = smooth_volume(empty_corner=content)
    wv = WaveletVolume.from_volume(vol, wavelet=wavelet, levels=levels)
    wv = wv if keep is None else wv.threshold(keep=keep)
    assert all((g.positions is None) == (keep is None) for g in wv.groups)
    if not content:
        wv.content_mask = None
    field = build(wv)
    j0 = wv.groups[0].wavelet.order
    rng = np.random.default_rng(7)
    x0 = rng.uniform(-6, 50, (300, 3))
    world = fine_to_world(x0, j0, wv.shape, wv.spacing, wv.origin)
    model = _content_field(wv) if content else (lambda p, d: wv.gradient(p) if d else wv.evaluate(p))
    ref = model(world, False)
    assert np.abs(ref).max() > 0.1
    np.testing.assert_allclose(pool_field(wv, field, x0), ref, rtol=0, atol=2e-6 * np.abs(ref).max())
    if wavelet != "haar":
        grad = pool_field(wv, field, x0[:60], derivative=True)[..., ::-1] / np.asarray(wv.spacing)[::-1]
        want = model(world[:60], True)
        cols = [c for g in wv.groups if g.wavelet.order > 1 for c in g.channels]  # Haar has no gradient
        np.testing.assert_allclose(grad[:, cols], want[:, cols], rtol=0, atol=2e-5 * np.abs(want).max())


@pytest.mark.parametrize("content", [False, True])
def test_block_bounds_hold_the_field(content):
    """|f| <= the bound of the block holding the point, every channel, on bricks of every level; nothing
    non-zero outside the blocks with a bound."""
    wv = WaveletVolume.from_volume(smooth_volume(empty_corner=content), wavelet="cubic", levels=3).threshold(keep=0.1)
    if not content:
        wv.content_mask = None
    field = build(wv)
    bound = field.bound_grid(field.pages[0])
    x0 = np.random.default_rng(3).uniform(-20, 64, (3000, 3))
    values = np.abs(pool_field(wv, field, x0)).max(axis=1)
    block = np.floor(x0 / BLOCK).astype(int) - field.origin * SUPER
    inside = np.all((block >= 0) & (block < bound.shape), axis=1)
    assert values[~inside].max(initial=0.0) == 0.0
    held = bound[tuple(block[inside].T)]
    assert np.all(values[inside] <= held * (1 + 1e-6)) and values[inside].max() > 0.1
    assert 0 < np.mean(bound > 0) < 1  # blocks of empty space are skipped


def test_bricks_hold_only_where_the_model_reaches():
    """A small ball in a big empty volume: few bricks, a pool far smaller than a dense fine grid."""
    n = 96
    z, y, x = np.mgrid[:n, :n, :n] - 20.0
    alpha = np.where(x ** 2 + y ** 2 + z ** 2 < 64, 0.2, 0.0)
    vol = clwave.Volume(np.stack([alpha, alpha, alpha, alpha], -1).astype(np.float32))
    wv = WaveletVolume.from_volume(vol, wavelet="cubic", levels=2).threshold(keep=0.05)
    field = build(wv)
    full = field.pages[0][field.pages[0] >= 0]
    assert 1 <= len(full) <= 8 and field.slot_bytes()[full].sum() < 16 * n ** 3 / 10  # the ball meets 2^3 bricks
    assert field.pool_bytes < 16 * n ** 3 / 5  # every detail's (docs/raytracing.md §8)
    image = RayTracer(wv).render(clwave.Camera(30, 20, size=24), tolerance=1e-3).image
    assert image[..., 3].max() > 0.5


def test_mixed_levels_across_brick_boundaries_trace_like_the_reference():
    """Rays through bricks of different levels (no content mask: smooth bricks stay coarse) against the NumPy
    oracle, which cuts every ray at every fine knot plane and sums the wavelets in closed form: X-ray segment
    integrals are exact, so they agree to rounding; at a tolerance, the kernel is within it of the converged
    oracle."""
    rgba = smooth_rgba(n=32)  # bricks of levels 0 to 3 as at 40^3; the oracle's cost grows with the knots a ray cuts
    wv = WaveletVolume.from_volume(rgba, wavelet="cubic", levels=3).threshold(keep=0.1)
    wv.content_mask = None
    tracer = RayTracer(wv)
    levels = set(tracer.bricks.levels[tracer.field_at(0).slots].tolist())
    assert len(levels) >= 3 and max(levels) == 3
    for cam, kw in ((clwave.Camera(25, 15, size=(2, 3)), dict(absorption=False)),
                    (clwave.Camera(-35, 30, size=(2, 2), perspective=True, distance=70.0), dict())):
        ref = raytrace_reference(wv, cam, tolerance=1e-9, tracer=tracer, **kw)
        assert np.abs(ref).max() > 0.05
        if kw:
            converged = tracer.render(cam, tolerance=1e-9, precision="double", **kw).image
            assert np.max(np.abs(converged - ref)) <= 1e-6 * np.abs(ref).max()
        assert np.max(np.abs(tracer.render(cam, tolerance=1e-3, **kw).image - ref)) <= 1e-3


def dense_reference_models():
    """The models of tests/data/dense_reference.npz (hydrogen 40^3 classified; images of the fine-grid path
    at float64, tolerance 1e-6, before its removal)."""
    rgba = TransferFunction.preset("hydrogen").classify(phantom("hydrogen", n=40))
    return dict(cubic=WaveletVolume.from_volume(rgba, wavelet="cubic", levels=3).threshold(keep=0.08),
                mixed=WaveletVolume.from_volume(rgba, wavelet=("cubic", "cubic", "cubic", "haar"),
                                                levels=2).threshold(keep=0.1),
                linear=WaveletVolume.from_volume(rgba, wavelet="linear", levels=2).threshold(keep=0.1))


DENSE_CAMERAS = dict(ortho=clwave.Camera(30, 20, size=40),
                     persp=clwave.Camera(-50, 35, size=32, perspective=True, distance=60.0, fov=40),
                     inside=clwave.Camera(10, 5, size=32, perspective=True, distance=6.0, fov=70))


@pytest.mark.slow
@pytest.mark.parametrize("model", ["cubic", "mixed", "linear"])
def test_images_equal_the_dense_path(model):
    reference = np.load(Path(__file__).parent / "data" / "dense_reference.npz")
    wv = dense_reference_models()[model]
    tracer = RayTracer(wv)
    for name, cam in DENSE_CAMERAS.items():
        for mode, kw in (("shaded", {}), ("xray", dict(absorption=False))):
            want = reference[f"{model}/{name}/{mode}"]
            got = tracer.render(cam, tolerance=1e-6, precision="double", **kw).image
            assert np.max(np.abs(got - want)) <= 1e-5, (name, mode)
            fast = tracer.render(cam, tolerance=1e-3, **kw).image  # float32 within the tolerance
            assert np.max(np.abs(fast - want)) <= 1e-3, (name, mode)


def out_of_core_model():
    """Long along z: many slabs of small cross-section, so that the pool outgrows what expanding a slab needs."""
    shape = (256, 40, 40)
    z, y, x = np.meshgrid(*[np.arange(n) / n for n in shape], indexing="ij")
    base = 0.4 + 0.3 * np.sin(3 * x) * np.cos(2 * y) + 0.2 * np.cos(5 * z)
    data = np.stack([base * (0.5 + 0.2 * c) for c in range(4)], -1) * np.array([1.0, 0.8, 0.6, 0.05])
    data[shape[0] // 2, shape[1] // 3, 2 * shape[2] // 3] += 2.0
    data[:16, :16, :16] = 0  # an empty corner: bricks where empty and non-empty voxels meet
    vol = clwave.Volume(data.astype(np.float32), spacing=(1.0, 0.9, 1.1))
    return WaveletVolume.from_volume(vol, wavelet="cubic", levels=3).threshold(keep=0.1)


def test_out_of_core_passes_equal_one_pass():
    """Bricks in host memory, rendered region by region in depth order with each ray's colour, transmittance
    and budgets carried between passes (docs/raytracing.md §6): the image of one pass, to rounding."""
    wv = out_of_core_model()
    whole, parts = RayTracer(wv), RayTracer(wv, device_memory="14MiB")
    assert whole.bricks.resident and not parts.bricks.resident and whole.bricks.pieces.any()  # mixed bricks too
    for cam, kw in ((clwave.Camera(30, 20, size=48), {}), (clwave.Camera(-60, 35, size=40), dict(absorption=False)),
                    (clwave.Camera(10, 5, size=40, perspective=True, distance=8.0, fov=70), {}),  # eye inside
                    (clwave.Camera(200, -30, size=32, perspective=True, distance=90.0), dict(shading=False))):
        a, b = whole.render(cam, tolerance=1e-3, **kw), parts.render(cam, tolerance=1e-3, **kw)
        assert a.meta["passes"] == 1 and b.meta["passes"] > 1 and b.meta["pool"] == "scratch file"
        for key in ("segments", "segments_by_lattice", "rays_terminated_early"):
            assert a.meta[key] == b.meta[key], key
        # a pass's first segment takes its first sample afresh: Simpson may halve a panel more or less there
        assert abs(a.meta["integrand_evaluations"] - b.meta["integrand_evaluations"]) <= 1e-3 * a.meta[
            "integrand_evaluations"]
        assert np.abs(a.image).max() > 0.5
        assert np.max(np.abs(a.image - b.image)) <= 1e-6 * np.abs(a.image).max()


def test_bricks_beyond_the_device_go_to_a_scratch_file_bit_for_bit(tmp_path, monkeypatch):
    """A pool bigger than the device budget is written to an unnamed scratch file in TMPDIR as it is expanded
    (docs/raytracing.md §6): what is read back equals the pool kept on the device, element for element, and the
    file takes room in TMPDIR, not in the process."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    wv = out_of_core_model()
    whole, parts = RayTracer(wv), RayTracer(wv, device_memory="14MiB")
    spill = parts.bricks.spill
    assert spill.folder == str(tmp_path) and spill.nbytes == whole.bricks.pool_bytes
    assert os.fstat(spill.file.fileno()).st_size == spill.nbytes and not os.listdir(tmp_path)  # unnamed
    assert np.array_equal(spilled(spill), whole.bricks.pool.get())


def test_no_room_for_the_scratch_file_is_a_clear_error(tmp_path, monkeypatch):
    """Too little room in TMPDIR for the bricks beyond the device, found before expanding, or a disk that fills
    while they are written: one OutputError naming the folder and the fix."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    wv = out_of_core_model()
    real = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(shutil, "disk_usage", lambda folder: real._replace(free=1 << 20))
    with pytest.raises(OutputError, match=f"need that much room in {tmp_path}.*set TMPDIR"):
        RayTracer(wv, device_memory="14MiB")
    monkeypatch.undo()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))

    def full(fd, data, offset):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "pwrite", full)
    with pytest.raises(OutputError, match=f"{tmp_path} failed: No space left on device.*set TMPDIR"):
        RayTracer(wv, device_memory="14MiB")


@pytest.mark.parametrize("cap,size,pool", [("4MiB", 8, None), ("14MiB", 500, "scratch file"), ("16MiB", 600, "device")])
def test_a_device_memory_cap_too_small_names_the_least_that_works(cap, size, pool):
    """Below two slabs' expansion (4 MiB), or below one brick beside a 500^2 or 600^2 image's buffers: an error
    naming the least cap that works, and that cap works. At the 500^2 image's the pool goes to the scratch file and
    the image renders in passes; at the 600^2 image's (above 22.7 MiB) the tracer keeps the pool on the device,
    where it must fit beside the image's buffers. (The model spans a few pixels: the rays cost little.)"""
    wv = out_of_core_model()
    cam = clwave.Camera(30, 20, size=size, extent=10.0 * size)

    def render(device_memory):
        return RayTracer(wv, device_memory=device_memory).render(cam, tolerance=1e-2)

    with pytest.raises(DeviceMemoryError, match="at least") as err:
        render(cap)
    least = re.search(r"at least ([\d.]+) (MiB|KiB)", str(err.value))
    res = render(f"{least.group(1)}{least.group(2)}")
    assert res.image.shape == (size, size, 4) and res.image.max() > 0
    assert pool is None or (res.meta["pool"] == pool and (res.meta["passes"] > 1) == (pool == "scratch file"))


def piece_flag(field: bricks.BrickField, x) -> tuple:
    """The slot the page table names at grid-0 point ``x`` (z, y, x) at full detail (-1: none) and, in a mixed
    brick, the flag of the piece holding ``x`` (field_piece in cl/raytrace/field_bspline.h; else -1)."""
    b = np.floor(x / BRICK).astype(int) - field.origin
    if np.any(b < 0) or np.any(b >= field.shape) or field.pages[0][tuple(b)] < 0:
        return -1, -1
    slot = field.pages[0][tuple(b)]
    coarse, table, n, side = field.mixes[slot]
    if coarse < 0:
        return slot, -1
    o, h = field.lattices[coarse][0], field.lattices[coarse][3]
    first = np.floor((np.floor(x / BRICK) * BRICK - o) / h) * (h // side)  # the brick's first coarse cell's piece
    k = np.clip((np.floor((x - o) / side) - first).astype(int), 0, n - 1)
    return slot, int(field.pieces[table + (k[0] * n + k[1]) * n + k[2]])


def piece_slot(field: bricks.BrickField, x) -> int:
    """The slot the march reads at grid-0 point ``x`` (z, y, x) at full detail: a mixed brick's coarse slot in its
    pieces flagged coarse, else the page table's."""
    slot, flag = piece_flag(field, x)
    return field.mixes[slot, 0] if flag == 1 else slot


def test_bernstein_floors_bound_each_cell_and_are_the_cubic_bezier_points():
    """pieces.alpha_floors: the least Bernstein coefficient of a cell's polynomial, at most the least of 6^3 samples
    of the closed-form B-spline sum on that cell; for the cubic, the Bezier points of the uniform B-spline
    (c0 + 4 c1 + c2) / 6, (2 c1 + c2) / 3, (c1 + 2 c2) / 3, (c1 + 4 c2 + c3) / 6 (closed form)."""
    from clwave.model.bspline import wavelet_for
    from clwave.raytrace.pieces import alpha_floors, bernstein

    cubic = wavelet_for("cubic")
    want = np.array([[1, 4, 1, 0], [0, 4, 2, 0], [0, 2, 4, 0], [0, 1, 4, 1]]) / 6.0
    np.testing.assert_allclose(bernstein(cubic.order)[:, ::-1], want, atol=1e-12)
    rng = np.random.default_rng(4)
    for name in ("linear", "quadratic", "cubic"):
        wav = wavelet_for(name)
        j = wav.order
        coef = rng.normal(0.2, 1.0, (j + 1, j + 1, j + 1))
        floors = alpha_floors(coef, wav)
        u = np.linspace(0, 1, 6)
        for cell in product(range(2), repeat=3):  # cell c's last coefficient is c + j - 1 (weights N_j(u + r))
            w = [np.array([[bspline(j, uu + (j - 1 - q)) for q in range(j)] for uu in u]) for _ in range(3)]
            box = coef[tuple(slice(c, c + j) for c in cell)]
            samples = np.einsum("ai,bj,ck,ijk->abc", w[0], w[1], w[2], box)
            assert floors[cell] <= samples.min() + 1e-12
        for parts in (1, 2):  # a constant is its own hull
            assert np.allclose(alpha_floors(np.full((j, j, j), 0.3), wav, parts), 0.3)
        # the floors of a cell's p^3 parts: each at most the part's samples, at least the whole cell's floor, and
        # the polynomial whose Bernstein coefficients they are is the B-spline sum on the part (its end values)
        parts = alpha_floors(coef, wav, 4)
        assert parts.shape == (8, 8, 8)
        assert np.all(parts.reshape(2, 4, 2, 4, 2, 4).min(axis=(1, 3, 5)) >= floors - 1e-12)
        for cell in product(range(2), repeat=3):
            box = coef[tuple(slice(c, c + j) for c in cell)]
            for part in product(range(4), repeat=3):
                w = [np.array([[bspline(j, uu + (j - 1 - q)) for q in range(j)] for uu in (p + u) / 4]) for p in part]
                samples = np.einsum("ai,bj,ck,ijk->abc", w[0], w[1], w[2], box)
                assert parts[tuple(4 * c + p for c, p in zip(cell, part))] <= samples.min() + 1e-12
    for part in range(3):  # a part's Bernstein coefficients end at the piece's values at the part's ends
        m = bernstein(4, part, 3)
        ends = np.array([[bspline(4, u + r) for r in range(4)] for u in (part / 3, (part + 1) / 3)])
        np.testing.assert_allclose(m[[0, -1]], ends, atol=1e-12)


def mixed_model(levels=2):
    """The classified ball of test_raytrace (a sharp edge in an empty margin) at 5 % (2 levels) or 2 % (3): its
    clamped bricks are level 1 (a piece a whole coarse cell) or 3 (a coarse cell 4^3 pieces) on their own, so
    they are mixed (docs/raytracing.md §3)."""
    from test_raytrace import classified_ball

    return WaveletVolume.from_volume(classified_ball(), "cubic", levels=levels).threshold(keep=0.05 if levels == 2
                                                                                           else 0.02)


@pytest.mark.parametrize("levels", [2, 3])
def test_mixed_pieces_are_the_clamped_field(levels):
    """Where a mixed brick's piece is marched on its coarse slot, the coarse slot's field is the content-clamped
    closed-form model (docs/raytracing.md §3, §4), with alpha >= 0; the other pieces read the clamped slot."""
    wv = mixed_model(levels)
    field = build(wv)
    mixed = np.flatnonzero(field.mixes[:, 0] >= 0)
    assert len(mixed) and field.pieces.any() and not field.pieces.all()
    assert np.all(field.levels[field.mixes[mixed, 0]] == levels - 1 + (levels == 3))
    assert np.all(field.levels[mixed] == 0) and np.all(field.mixes[mixed, 3] == 2)  # pieces of 2 fine cells
    rng = np.random.default_rng(5)
    x0 = rng.uniform(0, 32, (4000, 3))
    slots = np.array([piece_slot(field, x) for x in x0])
    coarse = np.isin(slots, field.mixes[mixed, 0])
    assert coarse.sum() > 40
    x0 = np.concatenate([x0[coarse][:120], x0[~coarse & (slots >= 0)][:40]])
    got = np.zeros((len(x0), 4))
    for i, x in enumerate(x0):  # pool_field with the piece's slot
        pages = field.pages[0].copy()
        pages[tuple(np.floor(x / BRICK).astype(int) - field.origin)] = piece_slot(field, x)
        got[i] = pool_field(wv, dataclasses.replace(field, pages=pages[None]), x[None])[0]
    ref = _content_field(wv)(fine_to_world(x0, 4, wv.shape, wv.spacing, wv.origin), False)
    assert np.abs(ref).max() > 0.05
    np.testing.assert_allclose(got, ref, rtol=0, atol=2e-6 * np.abs(ref).max())
    assert got[:120, 3].min() >= -1e-7
    # the pieces the march passes (flag 2): the content-clamped model is 0 there, and so is the clamped slot
    x0 = rng.uniform(0, 32, (4000, 3))
    x0 = x0[np.array([piece_flag(field, x)[1] for x in x0]) == 2][:60]
    assert len(x0) == 60
    assert np.all(_content_field(wv)(fine_to_world(x0, 4, wv.shape, wv.spacing, wv.origin), False) == 0)
    assert np.all(pool_field(wv, field, x0) == 0)


@pytest.mark.parametrize("levels", [2, 3])
def test_mixed_bricks_render_the_fine_function_with_fewer_segments(levels, monkeypatch):
    """Full detail of a model with mixed bricks: within the tolerance of the same tracer with every piece marched
    on the clamped fine slot (the function of today's bricks) and of a float64 render, with fewer segments (in
    passes: test_out_of_core_passes_equal_one_pass, whose model has mixed bricks); with level-3 bricks, fewer
    segments than with whole coarse cells as pieces, within the tolerance of that render too."""
    from clwave.raytrace import pieces

    wv = mixed_model(levels)
    tracer = RayTracer(wv)
    cam = clwave.Camera(30, 20, size=40)
    mixed = tracer.render(cam, tolerance=1e-3)
    exact = tracer.render(cam, tolerance=1e-6, precision="double").image
    tracer.bricks.pieces[:] = 0  # every piece on the fine slot
    tracer.bricks._static = None
    tracer.replace_pool(tracer.bricks.pool)
    fine = tracer.render(cam, tolerance=1e-3)
    assert np.abs(mixed.image).max() > 0.3
    for image in (mixed.image, fine.image):
        assert np.max(np.abs(image - exact)) <= 1e-3
    assert mixed.meta["segments"] < fine.meta["segments"] and mixed.meta["mixed_bricks"] == 8
    lattice = "2" if levels == 2 else "8+"
    assert mixed.meta["segments_by_lattice"][lattice] > 500 + fine.meta["segments_by_lattice"][lattice]
    if levels == 3:
        monkeypatch.setattr(pieces, "PIECE", 8)
        whole = RayTracer(wv).render(cam, tolerance=1e-3)
        assert np.max(np.abs(whole.image - exact)) <= 1e-3
        assert mixed.meta["segments"] < 0.97 * whole.meta["segments"]


@pytest.mark.parametrize("levels", [2, 3])
def test_piece_flags_equal_a_census_of_each_piece(levels):
    """pieces.mixed_pieces against one piece at a time.  Piece p of a mixed brick b covers fine cells
    ``o + h c0 + side p .. + side`` (c0: the coarse cell holding the brick's first cell, h its size, o the lattice
    origin); of those, the cells inside the brick decide: flag 2 where no content voxel reaches any of them (bounds.
    content_cells), 1 where only content voxels reach all of them and the least Bernstein coefficient of alpha on
    that part of its coarse cell (alpha_floors of the one cell) is >= 0, 0 otherwise; pieces outside the brick 0."""
    from clwave.raytrace.bounds import content_cells
    from clwave.raytrace.pieces import alpha_floors

    wv = mixed_model(levels)
    field = build(wv)
    pool = field.pool.get()
    lo, shape = field.origin * BRICK, np.array(field.shape) * BRICK
    some = content_cells(wv, lo, shape).astype(bool)
    every = content_cells(wv, lo, shape, every=True).astype(bool)
    alpha = next(gi for gi, g in enumerate(wv.groups) if 3 in g.channels)
    j = wv.groups[alpha].wavelet.order
    counts = np.zeros(3, int)
    for s in np.flatnonzero(field.mixes[:, 0] >= 0):
        coarse, first, k, side = (int(v) for v in field.mixes[s])
        o, h = float(field.lattices[coarse][0]), float(field.lattices[coarse][3])
        start = BRICK * field.bricks[s]
        c0 = np.floor((start - o) / h)
        frame, box = field.frames[coarse, alpha], field.boxes[coarse, alpha]
        coef = pool[box[3]:box[3] + np.prod(box[:3]), 3].reshape(box[2], box[1], box[0])  # z, y, x
        parts = int(h // side)
        floors = alpha_floors(coef, wv.groups[alpha].wavelet, parts)  # per part of each cell of the box
        for p in product(range(k), repeat=3):
            piece = o + h * c0 + side * np.array(p)
            a, b = np.maximum(piece, start).astype(int), np.minimum(piece + side, start + BRICK).astype(int)
            want = 0
            if np.all(b > a):
                cells = tuple(slice(x - y, z - y) for x, z, y in zip(a, b, lo))
                u = ((piece + side / 2)[::-1] - frame[:3]) * frame[3]  # the coarse cell's lattice coordinates (x, y, z)
                c = np.floor(u).astype(int)
                # cell c reads coefficients c - j + 1 .. c: its parts are floors[(c - j + 1) parts + ...]
                part = (c - j + 1) * parts + np.floor((u - c) * parts).astype(int)
                floor = floors[tuple(part[::-1])]
                if coarse != s and not some[cells].any():
                    want = 2
                elif (coarse == s or every[cells].all()) and floor >= 0:
                    want = 1
            assert field.pieces[first + (p[0] * k + p[1]) * k + p[2]] == want, (s, p)
            counts[want] += 1
    assert np.all(counts > 20), counts


@pytest.mark.parametrize("wavelet", [["cubic"] * 3 + ["haar"], ["linear"] * 3 + ["quadratic"]])
def test_content_cells_equal_a_census_of_the_voxels_reaching_each_cell(wavelet):
    """bounds.content_cells against one cell at a time: voxel k's B-spline of a group of order j reaches grid-0 cells
    [k + s, k + s + j) (s = (j0 - j) / 2, docs/raytracing.md §3); a cell is 1 where any voxel reaching it (of any
    group) is non-zero, or with ``every`` where all are (voxels beyond the volume are empty)."""
    from clwave.model.mask import ContentMask
    from clwave.raytrace.bounds import content_cells

    wv = WaveletVolume.from_volume(smooth_volume(n=10), wavelet=wavelet, levels=1)
    mask = np.random.default_rng(9).random(wv.shape) < 0.7
    mask[1:8, 1:9, 2:9] = True
    wv.content_mask = ContentMask.of(mask)
    j0 = wv.groups[0].wavelet.order
    origin, shape = np.array([-3, -1, 4]), np.array([9, 8, 9])
    some, every = content_cells(wv, origin, shape), content_cells(wv, origin, shape, every=True)
    for c in product(*(range(o, o + n) for o, n in zip(origin, shape))):
        reach = set()
        for g in wv.groups:
            j, s = g.wavelet.order, (j0 - g.wavelet.order) / 2.0
            reach |= set(product(*(range(int(np.floor(x - j - s)) + 1, int(np.ceil(x + 1 - s))) for x in c)))
        values = [bool(np.all(np.array(k) >= 0) and np.all(np.array(k) < wv.shape) and mask[k]) for k in reach]
        at = tuple(np.array(c) - origin)
        assert some[at] == any(values) and every[at] == all(values), c
    assert some.any() and not some.all() and every.any() and not np.array_equal(some, every)
