"""Each stage of the splatting pipeline (clwave.splat.stages) against its NumPy oracle
(clwave.splat.reference) on small random inputs, one test per stage: each stage gets its inputs
from the oracle of the stages before it, so a failure names the stage that broke.

Integer stages must be exactly equal; the accumulation to float32 rounding."""

import itertools

import numpy as np
import pyopencl.array as cla
import pytest

from clwave.device.memory import device_budget
from clwave.splat import reference
from clwave.splat.stages import Stages, bin_chunks
from clwave.splat.tables import GATHER_U, LINEAR_U, LINEAR_V, pack_texture

#: two framebuffers (width, height, first tile, first pixel), sizes not multiples of the 16-pixel
#: tile: 3 x 3 tiles, then 2 x 2
LAYERS = np.array([(45, 37, 0, 0), (29, 21, 9, 45 * 37)], np.int32)
TILES, PIXELS = 13, 45 * 37 + 29 * 21
TEX_LAYER = np.array([(0, 0), (0, 1), (0, 2), (0, 3), (0, 4), (1, 0), (1, 1), (1, 2), (0, 5), (1, 3), (0, 6), (1, 4)],
                     np.int32)


#: cells, u linear / v cells, u cells / v linear, bilinear; u texels coarser than the pixel (a magnified view)
#: with v linear, and with v cells
LOOKUPS = (0, LINEAR_U, LINEAR_V, LINEAR_U | LINEAR_V, GATHER_U | LINEAR_V, GATHER_U)


def random_scene(rng, n=400, n_tex=12, beyond=0.0):
    """Random splats of random textures; ``beyond``: the boxes of textures gathered along u (``GATHER_U``) reach
    that many pixels beyond their first and last texel, where the kernels read zeros (the kernels' boxes round
    inward, so only this scene reaches there)."""
    coef = np.zeros((n + 7, 4), np.int32)
    coef[:, :3] = rng.integers(-3, 12, (n + 7, 3))
    coef[:, 3] = rng.integers(0, 3, n + 7) * 8 + rng.integers(0, 8, n + 7)
    band_tex = rng.integers(-1, n_tex, 64).astype(np.int32)
    band_origin = rng.uniform(-10, 50, (64, 2)).astype(np.float32)
    step_col = rng.uniform(-3, 3, (64, 4)).astype(np.float32)
    step_row = rng.uniform(-3, 3, (64, 4)).astype(np.float32)
    ints, maps, boxes, pool, textures, off = [], [], [], [np.zeros(16)], [], 16
    for i in range(n_tex):
        nu, nv = rng.integers(2, 30, 2)
        cu, cv = rng.uniform(0, nu - 1), rng.uniform(0, nv - 1)
        data = rng.standard_normal((nv, nu)).astype(np.float32)
        lookup = LOOKUPS[i % len(LOOKUPS)]
        # along a linear axis texels are 1/P pixel (u: P phase planes) or, along u gathered, coarser than the
        # pixel; along a cell axis any step with nearest lookup, the box reaching half a texel beyond the first
        # and last
        P = int(rng.integers(1, 6))
        su = float(P) if lookup & LINEAR_U else rng.uniform(0.05, 0.99) if lookup & GATHER_U else rng.uniform(0.2, 3.0)
        sv = float(P) if lookup == LINEAR_U | LINEAR_V else rng.uniform(0.2, 3.0)
        planes = pack_texture(data, P if lookup & LINEAR_U else 1)
        ru, rv = (0.0 if lookup & (LINEAR_U | GATHER_U) else 0.5), (0.0 if lookup & LINEAR_V else 0.5)
        reach = beyond if lookup & GATHER_U else 0.0
        boxes.append((-(cu + ru) / su - reach, (nu - 1 + ru - cu) / su + reach, -(cv + rv) / sv,
                      (nv - 1 + rv - cv) / sv))
        ints.append((off, planes.shape[2], planes.shape[1], lookup))
        maps.append((cu, cv, su, sv))
        pool.append(planes.ravel())
        textures.append((data, cu, cv, lookup, su, sv))
        off += planes.size
    values = rng.standard_normal((n + 7, 4)).astype(np.float32)
    return dict(coef=coef, band_tex=band_tex, band_origin=band_origin, step_col=step_col, step_row=step_row,
                tex_layer=TEX_LAYER[:n_tex], layers=LAYERS,
                tex_box=np.array(boxes, np.float32), tex_int=np.array(ints, np.int32),
                tex_map=np.array(maps, np.float32), texels=np.concatenate(pool + [np.zeros(32)]).astype(np.float32),
                values=values, n=n, first=7, textures=textures)


VARIANTS = [("cpu", 4), ("cpu", 1), ("gpu", 4), ("gpu", 1)]  # accumulation kernel, channels


@pytest.fixture
def scene(rng):
    """A random scene and every stage's oracle output, in pipeline order."""
    return with_oracles(random_scene(rng))


def with_oracles(s):
    """Scene ``s`` with every stage's oracle output, in pipeline order."""
    n, first = s["n"], s["first"]
    s["centre"], s["bbox"], s["stex"], s["count"] = reference.project(
        s["coef"], first, s["band_tex"], s["band_origin"], s["step_col"], s["step_row"], s["tex_box"],
        s["tex_layer"], s["layers"], n)
    assert 0 < np.count_nonzero(s["count"]) < n  # the scene has both visible and culled splats
    assert set(s["tex_layer"][s["stex"][s["count"] > 0], 0]) == {0, 1}  # both layers are drawn into
    s["total"] = int(s["count"].sum())
    s["textures_per_layer"] = int(s["tex_layer"][:, 1].max()) + 1
    s["ranges"], s["vals"] = reference.bin_by_tile(s["bbox"], s["stex"], s["tex_layer"], s["layers"], TILES)
    return s


def upload(q, s):
    return {k: cla.to_device(q, v) for k, v in s.items() if isinstance(v, np.ndarray)}


def chunkings(cc, n, runs):
    return (1, 7, bin_chunks(n, runs, cc.info, device_budget(cc)))  # one chunk, a few uneven ones, the renderer's


def counts(s, chunks):
    """The oracle's per-chunk counts, (chunks, runs)."""
    return reference.count_tiles(s["bbox"], s["stex"], s["tex_layer"], s["layers"], s["textures_per_layer"],
                                 -(-s["n"] // chunks), chunks, TILES)


def test_project(cc, scene):
    st, q, n = Stages(cc, 4), cc.queue, scene["n"]
    d = upload(q, scene)
    centre, bbox = cla.empty(q, (n, 2), np.float32), cla.empty(q, (n, 4), np.int32)
    stex, count = cla.empty(q, (n,), np.int32), cla.empty(q, (n,), np.uint32)
    st.project(n, scene["first"], d["coef"], d, centre, bbox, stex, count)
    assert np.array_equal(centre.get(), scene["centre"])
    assert np.array_equal(bbox.get(), scene["bbox"]) and np.array_equal(stex.get(), scene["stex"])
    assert np.array_equal(count.get(), scene["count"])


def test_count(cc, scene):
    st, q, n = Stages(cc, 4), cc.queue, scene["n"]
    d, runs = upload(q, scene), TILES * scene["textures_per_layer"]
    for chunks in chunkings(cc, n, runs):
        table = cla.empty(q, (chunks * runs,), np.uint32)
        st.count(n, chunks, TILES, scene["textures_per_layer"], scene["first"], d["bbox"], d["centre"], d["stex"],
                 d["values"], d, table)
        assert np.array_equal(table.get(), counts(scene, chunks).ravel())


@pytest.mark.parametrize("rows, cols", [(1, 1), (7, 13), (13, 7), (40, 65)])
def test_transpose(cc, rng, rows, cols):
    src = rng.integers(0, 2**32, rows * cols, dtype=np.uint32)
    d_src, d_dst = cla.to_device(cc.queue, src), cla.empty(cc.queue, (rows * cols,), np.uint32)
    Stages(cc, 4).transpose(rows, cols, d_src, d_dst)
    assert np.array_equal(d_dst.get(), src.reshape(rows, cols).T.ravel())


def test_each_stage_launches_one_work_group_size_whatever_the_count(cc, scene, monkeypatch):
    """PoCL builds a kernel anew for each work-group size (and derives one from the global size where none is
    given): every stage gives its own, the same for any count, the global size in whole groups."""
    from clwave.device.kernels import Kernel

    launches, call = [], Kernel.__call__

    def record(self, kernels, queue, global_size, local_size, *args, **kwargs):
        launches.append((self.name, global_size[0], local_size))
        return call(self, kernels, queue, global_size, local_size, *args, **kwargs)

    monkeypatch.setattr(Kernel, "__call__", record)
    st, q = Stages(cc, 4), cc.queue
    d, runs = upload(q, scene), TILES * scene["textures_per_layer"]
    for n in (scene["n"], 123, 1):
        centre, bbox = cla.empty(q, (n, 2), np.float32), cla.empty(q, (n, 4), np.int32)
        stex, count = cla.empty(q, (n,), np.int32), cla.empty(q, (n,), np.uint32)
        st.project(n, scene["first"], d["coef"], d, centre, bbox, stex, count)
        for chunks in chunkings(cc, n, runs):
            table = cla.empty(q, (chunks * runs,), np.uint32)
            st.count(n, chunks, TILES, scene["textures_per_layer"], scene["first"], bbox, centre, stex, d["values"],
                     d, table)
            st.transpose(chunks, runs, table, cla.empty_like(table))
        st.ranges(n % TILES + 1, scene["textures_per_layer"], 1, 0, cla.zeros(q, (runs,), np.uint32),
                  cla.empty(q, (TILES, 2), np.uint32))
    sizes = {}
    for name, global_size, local_size in launches:
        assert local_size is not None and global_size % local_size[0] == 0, name
        sizes.setdefault(name, set()).add(local_size)
    assert set(sizes) == {"splat_project", "splat_chunk_tiles", "transpose_counts", "tile_ranges"}
    assert all(len(s) == 1 for s in sizes.values()), sizes


@pytest.mark.parametrize("variant", ["cpu", "gpu"])
def test_scan(cc, rng, variant):
    """Exclusive prefix sums: NumPy's for the CPU variant, pyopencl's scan kernel for the GPU one."""
    values = rng.integers(0, 50, 1000, dtype=np.uint32)
    d_in, d_out = cla.to_device(cc.queue, values), cla.empty(cc.queue, (1000,), np.uint32)
    Stages(cc, 4, variant=variant).scan(d_in, d_out)
    assert d_out.get().tolist() == list(itertools.accumulate(values.tolist(), initial=0))[:-1]


def test_ranges(cc, scene):
    st, q = Stages(cc, 4), cc.queue
    runs = TILES * scene["textures_per_layer"]
    for chunks in chunkings(cc, scene["n"], runs):
        starts = np.concatenate([[0], np.cumsum(counts(scene, chunks).T)[:-1]]).astype(np.uint32)  # run-major
        ranges = cla.empty(q, (TILES, 2), np.uint32)
        st.ranges(TILES, scene["textures_per_layer"], chunks, scene["total"], cla.to_device(q, starts), ranges)
        assert np.array_equal(ranges.get(), scene["ranges"])


@pytest.mark.parametrize("channels", [4, 1])
def test_place(cc, scene, channels):
    st, q, n = Stages(cc, channels), cc.queue, scene["n"]
    d, runs = upload(q, scene), TILES * scene["textures_per_layer"]
    expected = reference.records(scene["ranges"], scene["vals"], scene["first"], scene["centre"], scene["bbox"],
                                 scene["stex"], scene["values"], scene["layers"], channels)
    for chunks in chunkings(cc, n, runs):
        starts = np.concatenate([[0], np.cumsum(counts(scene, chunks).T)[:-1]]).astype(np.uint32)
        cursors = cla.to_device(q, np.ascontiguousarray(starts.reshape(-1, chunks).T).ravel())  # chunk-major
        records = cla.empty(q, expected.shape, np.uint32)
        st.place(n, chunks, TILES, scene["textures_per_layer"], scene["first"], d["bbox"], d["centre"], d["stex"],
                 d["values"], d, cursors, records)
        assert np.array_equal(records.get(), expected)


@pytest.mark.parametrize("beyond", [0.0, 3.0])
@pytest.mark.parametrize("variant, channels", VARIANTS)
def test_accumulate(cc, rng, variant, channels, beyond):
    """The image against the oracle's; ``beyond``: boxes of gathered textures reaching 3 pixels beyond their texels,
    read as zeros (the oracle's ring) where they once weighted the edge texel by the position's fraction."""
    scene = with_oracles(random_scene(rng, beyond=beyond))
    st, q = Stages(cc, channels, variant), cc.queue
    d = upload(q, scene)
    records = cla.to_device(q, reference.records(scene["ranges"], scene["vals"], scene["first"], scene["centre"],
                                                 scene["bbox"], scene["stex"], scene["values"], scene["layers"],
                                                 channels))
    images = []
    for _ in range(2):  # accumulates onto what is there; a second run repeats the first bit for bit
        fb = cla.to_device(q, np.full((PIXELS, 4), 0.5, np.float32))
        st.accumulate(TILES, len(LAYERS), d, cla.to_device(q, scene["ranges"]), records, fb)
        images.append(fb.get())
    assert np.array_equal(images[0], images[1])
    expected = 0.5 + reference.accumulate(scene["ranges"], scene["vals"], scene["first"], scene["centre"],
                                          scene["bbox"], scene["stex"], scene["values"], scene["textures"],
                                          scene["layers"], channels)
    assert np.abs(expected - 0.5).max() > 1  # splats did land
    drawn = scene["stex"][scene["count"] > 0]
    assert all(np.isin(drawn, np.flatnonzero(scene["tex_int"][:, 3] == lookup)).sum() > 10 for lookup in LOOKUPS)
    # float32 sums of float32 texel coordinates: rounding at 1e-5 of the image's magnitude
    assert np.abs(images[0] - expected).max() <= 1e-5 * np.abs(expected).max()
    if channels == 1:  # the other channels of the framebuffer keep their values
        assert np.array_equal(images[0][:, 1:], np.full((PIXELS, 3), 0.5, np.float32))


def test_stages_in_bands_of_one_item_give_the_results_of_long_launches(cc, scene, monkeypatch):
    """Count, place and accumulate go in bounded launches (Ctrl-C is taken between them,
    clwave.device.kernels.in_bands): one splat of every chunk, or one tile, a launch gives the oracle's
    counts and records and the image of long launches bit for bit."""
    from clwave.device import kernels

    st, q, n = Stages(cc, 4), cc.queue, scene["n"]
    d, runs, textures = upload(q, scene), TILES * scene["textures_per_layer"], scene["textures_per_layer"]
    chunks = 7
    expected = reference.records(scene["ranges"], scene["vals"], scene["first"], scene["centre"], scene["bbox"],
                                 scene["stex"], scene["values"], scene["layers"], 4)
    starts = np.concatenate([[0], np.cumsum(counts(scene, chunks).T)[:-1]]).astype(np.uint32)
    ranges = cla.to_device(q, scene["ranges"])
    images = []
    for seconds in (1e9, 0.0):  # bands growing to the whole (twice the last), then a band of one item each
        monkeypatch.setattr(kernels, "LAUNCH_SECONDS", seconds)
        table = cla.empty(q, (chunks * runs,), np.uint32)
        st.count(n, chunks, TILES, textures, scene["first"], d["bbox"], d["centre"], d["stex"], d["values"], d, table)
        assert np.array_equal(table.get(), counts(scene, chunks).ravel())
        cursors = cla.to_device(q, np.ascontiguousarray(starts.reshape(-1, chunks).T).ravel())
        records = cla.empty(q, expected.shape, np.uint32)
        st.place(n, chunks, TILES, textures, scene["first"], d["bbox"], d["centre"], d["stex"], d["values"], d,
                 cursors, records)
        assert np.array_equal(records.get(), expected)
        fb = cla.zeros(q, (PIXELS, 4), np.float32)
        st.accumulate(TILES, len(LAYERS), d, ranges, records, fb)
        images.append(fb.get())
    assert np.abs(images[0]).max() > 1 and np.array_equal(images[0], images[1])
