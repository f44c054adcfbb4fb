"""Each cone-beam kernel stage (cl/splat/cone.cl, docs/splatting.md §8) against its NumPy oracle
(clwave.splat.reference: slope_cells, project_cone, records, accumulate_cone) on a small random scene: two layers
(framebuffers), a rotated frame, splats behind the eye and beyond the slope grid, textures on the grid's nodes and on
nodes 2 and 3 times closer (refined bands, docs/splatting.md §8); each stage gets its inputs from the oracles of the
stages before it, as tests/test_splat_kernels.py does for orthographic views."""

import functools
from types import SimpleNamespace

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
import pytest

from clwave.model.transform import Band
from clwave.splat import reference
from clwave.splat.cone_cells import pack_nodes, slope_cells
from clwave.splat.stages import Stages
from clwave.splat.tables import POOL_GUARD, set_texture_tables

LAYERS = np.array([(45, 37, 0, 0), (29, 21, 9, 45 * 37)], np.int32)  # as test_splat_kernels: 3 x 3 tiles, 2 x 2
TILES, PIXELS = 13, 45 * 37 + 29 * 21
TEX_LAYER = np.array([(0, 0), (0, 1), (0, 2), (0, 3), (0, 4), (1, 0), (1, 1), (1, 2)], np.int32)
COUNT = (5, 4)  # slope nodes along u, v
REFINE = (1, 2, 1, 3, 1, 1, 2, 1)  # each texture's slope refinement: its nodes r to the grid's step


def cone_scene(rng, n=300):
    q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    n_, u, v = q.T  # a random orthonormal frame
    eye = rng.uniform(-5, 5, 3)
    layer_slope = np.zeros((2, 4), np.float32)
    layer_slope[0, :2] = (0.02, 0.025)
    layer_slope[1, :2] = 2 * layer_slope[0, :2]  # a coarse layer of factor 2
    s0 = rng.uniform(-0.05, 0.05, 2)
    step = np.array([0.16, 0.2])  # the grid covers slopes s0 - 0.35 .. s0 + 0.29 (u), .. + 0.25 (v): pixels beyond
    cone = np.zeros((6, 4), np.float32)
    cone[0, :3], cone[1, :3], cone[2, :3], cone[3, :3] = eye, n_, u, v
    cone[4] = (*s0, *(s0 - 0.35))
    cone[5] = (*(1.0 / step), *COUNT)
    coef = np.zeros((n + 7, 4), np.int32)
    coef[:, :3] = rng.integers(-3, 12, (n + 7, 3))
    coef[:, 3] = rng.integers(0, 3, n + 7) * 8 + rng.integers(0, 8, n + 7)
    band_tex = rng.integers(-1, len(TEX_LAYER), 64).astype(np.int32)
    depth, lateral = rng.uniform(4, 40, 64), rng.uniform(-0.3, 0.3, (64, 2))
    depth[::8] = -3.0  # bands behind the eye
    band_world = np.zeros((64, 4), np.float32)
    band_world[:, :3] = eye + depth[:, None] * (-n_ + lateral[:, :1] * u + lateral[:, 1:] * v)
    band_step = np.zeros((64, 4), np.float32)
    band_step[:, :3] = rng.uniform(0.3, 1.6, (64, 3))
    textures, boxes, ints, maps, pool, offset = [], [], [], [], [np.zeros(POOL_GUARD)], POOL_GUARD
    for r in REFINE:
        nu, nv = rng.integers(2, 24, 2)
        count = [(k - 1) * r + 1 for k in COUNT]
        nodes = rng.standard_normal((count[0] * count[1], nv, nu)).astype(np.float32)
        cu, cv, h_u, h_v = rng.uniform(0, nu - 1), rng.uniform(0, nv - 1), *rng.uniform(0.05, 0.8, 2)
        cells = reference.slope_cells(nodes, count)[0]
        boxes.append((-cu * h_u, (nu - 1 - cu) * h_u, -cv * h_v, (nv - 1 - cv) * h_v))
        ints.append((offset, nu + 2, r, nv + 2))
        maps.append((cu, cv, 1.0 / h_u, 1.0 / h_v))
        pool.append(cells.ravel())
        offset += cells.size
        textures.append((nodes, np.float32(cu), np.float32(cv), np.float32(1.0 / h_u), np.float32(1.0 / h_v)))
    t = SimpleNamespace()
    set_texture_tables(t, boxes, ints, maps, [tuple(x) for x in TEX_LAYER], pool)
    return dict(coef=coef, band_tex=band_tex, band_world=band_world, band_step=band_step, tex_box=t.tex_box,
                tex_layer=t.tex_layer, layers=LAYERS, layer_slope=layer_slope, cone=cone, tex_int=t.tex_int,
                tex_map=t.tex_map, texels=t.texels, values=rng.standard_normal((n + 7, 4)).astype(np.float32),
                n=n, first=7, textures=textures)


@pytest.fixture(scope="module")
def scene():
    """The scene, shared by the module's tests (they only read it)."""
    s = cone_scene(np.random.default_rng(12345))
    s["centre"], s["bbox"], s["stex"], s["count"], s["slack"] = reference.project_cone(
        s["coef"], s["first"], s["band_tex"], s["band_world"], s["band_step"], s["tex_box"], s["tex_layer"],
        s["layers"], s["layer_slope"], s["cone"], s["n"])
    shown = s["count"] > 0
    assert 0 < np.count_nonzero(shown) < s["n"] and np.any(s["centre"][:, 2] <= 0)  # drawn, culled, behind the eye
    assert set(s["tex_layer"][s["stex"][shown], 0]) == {0, 1}
    s["centre"] = s["centre"].astype(np.float32)
    s["ranges"], s["vals"] = reference.bin_by_tile(s["bbox"], s["stex"], s["tex_layer"], s["layers"], TILES)
    return s


def upload(q, s):
    return {k: cla.to_device(q, v) for k, v in s.items() if isinstance(v, np.ndarray)}


def test_project_cone(cc, scene):
    st, q, n = Stages(cc, 4, perspective=True), cc.queue, scene["n"]
    d = upload(q, scene)
    centre, bbox = cla.empty(q, (n, 4), np.float32), cla.empty(q, (n, 4), np.int32)
    stex, count = cla.empty(q, (n,), np.int32), cla.empty(q, (n,), np.uint32)
    st.project(n, scene["first"], d["coef"], d, centre, bbox, stex, count)
    assert np.array_equal(stex.get(), scene["stex"])
    got, want = centre.get(), scene["centre"]
    shown = (scene["stex"] >= 0) & (want[:, 2] > 0)
    assert np.allclose(got[:, 2], want[:, 2], rtol=1e-5, atol=1e-4)
    assert np.allclose(got[shown, :2], want[shown, :2], rtol=1e-5, atol=1e-3)  # pixels: float32 over a depth
    # boxes equal wherever float32 rounding cannot move an edge across a whole pixel
    sure = scene["slack"] > 1e-3
    assert sure.mean() > 0.95
    assert np.array_equal(bbox.get()[sure], scene["bbox"][sure]) and np.array_equal(count.get()[sure],
                                                                                    scene["count"][sure])


def test_place_cone_records(cc, scene):
    # binning (cl/splat/bin.cl, shared) writes the perspective records: the depth in the second uint4's w
    st, q, n = Stages(cc, 1, perspective=True), cc.queue, scene["n"]
    d = upload(q, scene)
    textures = int(scene["tex_layer"][:, 1].max()) + 1
    chunks = 5
    counts = reference.count_tiles(scene["bbox"], scene["stex"], scene["tex_layer"], scene["layers"], textures,
                                   -(-n // chunks), chunks, TILES)
    starts = np.concatenate([[0], np.cumsum(counts.T)[:-1]]).astype(np.uint32)
    cursors = cla.to_device(q, np.ascontiguousarray(starts.reshape(-1, chunks).T).ravel())
    expected = reference.records(scene["ranges"], scene["vals"], scene["first"], scene["centre"], scene["bbox"],
                                 scene["stex"], scene["values"], scene["layers"], 1)
    assert expected.shape[1] == 8 and np.any(expected[:, 7])  # two uint4s, the depth in the last word
    records = cla.empty(q, expected.shape, np.uint32)
    st.place(n, chunks, TILES, textures, scene["first"], d["bbox"], d["centre"], d["stex"], d["values"], d,
             cursors, records)
    assert np.array_equal(records.get(), expected)


@pytest.fixture(scope="module")
def accumulated(scene):
    """The oracle's framebuffer (splats over 0.5) for a number of channels: made once for both work-group layouts,
    which must give the same sums (about 16 CPU s).  The oracle adds each channel on its own, so fewer channels are
    the first of the four's sums bit for bit, the rest untouched."""
    @functools.cache
    def expected(channels):
        if channels < 4:
            fb = expected(4).copy()
            fb[:, channels:] = 0.5
            return fb
        fb = 0.5
        for r in set(REFINE):  # each refinement's own slope grid (r times the nodes), the others' textures 0
            cone = scene["cone"].copy()
            cone[5] = (*(r * cone[5, :2]), *((cone[5, 2:] - 1) * r + 1))
            textures = [t if own == r else (np.zeros((int(cone[5, 2] * cone[5, 3]), 1, 1)), 0, 0, 1, 1)
                        for t, own in zip(scene["textures"], REFINE)]
            fb = fb + reference.accumulate_cone(
                scene["ranges"], scene["vals"], scene["first"], scene["centre"], scene["bbox"], scene["stex"],
                scene["values"], textures, scene["layers"], scene["layer_slope"], cone, channels)
        return fb
    return expected


@pytest.mark.parametrize("variant, channels", [("cpu", 4), ("cpu", 1), ("gpu", 4), ("gpu", 1)])
def test_accumulate_cone(cc, scene, accumulated, variant, channels):
    st, q = Stages(cc, channels, variant, perspective=True), cc.queue
    d = upload(q, scene)
    records = cla.to_device(q, reference.records(scene["ranges"], scene["vals"], scene["first"], scene["centre"],
                                                 scene["bbox"], scene["stex"], scene["values"], scene["layers"],
                                                 channels))
    fb = cla.to_device(q, np.full((PIXELS, 4), 0.5, np.float32))
    st.accumulate(TILES, len(LAYERS), d, cla.to_device(q, scene["ranges"]), records, fb)
    expected = accumulated(channels)
    assert np.abs(expected - 0.5).max() > 1  # splats did land
    got = fb.get()
    assert np.abs(got - expected).max() <= 1e-5 * np.abs(expected).max()
    if channels == 1:  # the other channels of the framebuffer keep their values
        assert np.array_equal(got[:, 1:], np.full((PIXELS, 3), 0.5, np.float32))


@pytest.mark.parametrize("count, quasi, spare", [((5, 4), True, False), ((5, 4), False, False), ((2, 3), True, True)])
def test_cone_cells(cc, rng, count, quasi, spare):
    # the texel pool made on the device from each texture's nodes (cl/splat/cone_cells.cl), textures of two layers
    # (one refined twice, one three times: their nodes r to the grid's step) and a band not drawn, against the
    # oracle: the cells, their guards of zeros, each node's largest magnitude and the grid cells' bounds; written
    # over a spare node array and pool of an earlier view (NaNs here) too
    bands = [Band(level, key, (1, 1, 1), 0)
             for level, key in ((2, "aaa"), (2, "aad"), (1, "dda"), (1, "ddd"), (1, "add"))]
    layer_of = {(2, "aaa"): 1, (2, "aad"): 0, (1, "dda"): 0, (1, "ddd"): 1}
    refine = {(1, "dda"): 2, (2, "aaa"): 3}
    textures = {}
    for b in bands:
        nu, nv = rng.integers(1, 30, 2)
        r = refine.get((b.level, b.key), 1)
        nodes = rng.standard_normal((((count[0] - 1) * r + 1) * ((count[1] - 1) * r + 1), nv + 3, nu + 2))
        textures[(b.level, b.key)] = SimpleNamespace(data=nodes.astype(np.float32)[:, 2:-1, 1:-1], centre_u=nu / 2,
                                                     centre_v=nv / 2, h_u=0.5, h_v=0.25)  # a view, as the host's
    old = np.full(10**5, np.nan, np.float32) if spare else None
    packed = pack_nodes(SimpleNamespace(bands=bands), textures, layer_of, 2, count, None, old, refine)
    assert (packed["nodes"] is old) == spare
    pool = cl.Buffer(cc.ctx, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR, hostbuf=old) if spare else None
    pool, cell_peaks = slope_cells(cc, packed, count, quasi, pool)
    got = np.empty(packed["pool_floats"], np.float32)
    cl.enqueue_copy(cc.queue, got, pool)
    order = [(2, "aad"), (1, "dda"), (2, "aaa"), (1, "ddd")]  # each layer's bands in the group's order
    assert np.array_equal(packed["tex_layer"], [(0, 0), (0, 1), (1, 0), (1, 1)])
    assert np.array_equal(packed["tex_int"][:, 2], [1, 2, 3, 1])
    end = POOL_GUARD
    for t, (band, (offset, _, r, _)) in enumerate(zip(order, packed["tex_int"])):
        own = [(k - 1) * r + 1 for k in count]
        cells, node_peaks = reference.slope_cells(textures[band].data, own, quasi)
        assert offset == end and np.array_equal(got[offset:offset + cells.size], cells.ravel())
        end = offset + cells.size
        node_peaks = node_peaks.reshape(own[1], own[0])
        assert np.array_equal(cell_peaks[t, 0, -1, 0, -1], node_peaks.max())
        assert np.array_equal(cell_peaks[t, -1, -1, -1, -1], node_peaks[-r - 1:, -r - 1:].max())
        assert np.array_equal(cell_peaks[t, 0, 0, 0, 0], node_peaks[:r + 1, :r + 1].max())
    assert not np.any(got[:POOL_GUARD]) and not np.any(got[end:end + 2 * POOL_GUARD])  # the guards of zeros
