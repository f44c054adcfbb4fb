"""Each splatting kernel against its NumPy reference on small random inputs (clwave.reference).

Integer stages must be exactly equal; the accumulation to float32 rounding."""

import numpy as np
import pyopencl.array as cla
import pytest
from pyopencl.scan import ExclusiveScanKernel

from clwave import programs, reference
from clwave.splat import LINEAR_U, LINEAR_V, bin_chunks, pack_texture

#: two framebuffers (width, height, first tile, first pixel), sizes not multiples of the 16-pixel
#: tile: 3 x 3 tiles, then 2 x 2
LAYERS = np.array([(45, 37, 0, 0), (29, 21, 9, 45 * 37)], np.int32)
TILES, PIXELS = 13, 45 * 37 + 29 * 21
TEX_LAYER = np.array([(0, 0), (0, 1), (0, 2), (0, 3), (0, 4), (1, 0), (1, 1), (1, 2)], np.int32)


LOOKUPS = (0, LINEAR_U, LINEAR_V, LINEAR_U | LINEAR_V)  # cells, u linear / v cells, u cells / v linear, bilinear


def random_scene(rng, n=400, n_tex=8):
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
        lookup = LOOKUPS[i % 4]
        # along a linear axis texels are 1/P pixel (u: P phase planes), along a cell axis any step
        # with nearest lookup, the box reaching half a texel beyond the first and last
        P = int(rng.integers(1, 6))
        su = float(P) if lookup & LINEAR_U else rng.uniform(0.2, 3.0)
        sv = float(P) if lookup == LINEAR_U | LINEAR_V else rng.uniform(0.2, 3.0)
        planes = pack_texture(data, P if lookup & LINEAR_U else 1)
        ru, rv = (0.0 if lookup & LINEAR_U else 0.5), (0.0 if lookup & LINEAR_V else 0.5)
        boxes.append((-(cu + ru) / su, (nu - 1 + ru - cu) / su, -(cv + rv) / sv, (nv - 1 + rv - cv) / sv))
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


@pytest.mark.parametrize("px, channels", [(256, 4), (256, 1), (1, 4), (1, 1)])
def test_every_stage_equals_its_reference(cc, rng, px, channels):
    s = random_scene(rng)
    q, n, first = cc.queue, s["n"], s["first"]
    ks = programs.build(cc, ["splat_bin.cl", "splat_raster.cl"], {"CLW_PX": px, "CLW_CHANNELS": channels})
    d = {k: cla.to_device(q, v) for k, v in s.items() if isinstance(v, np.ndarray)}
    centre, bbox = cla.empty(q, (n, 2), np.float32), cla.empty(q, (n, 4), np.int32)
    stex, counts = cla.empty(q, (n,), np.int32), cla.empty(q, (n,), np.uint32)
    ks.splat_project(q, (n,), None, np.uint32(n), np.uint32(first), d["coef"].data, d["band_tex"].data,
                     d["band_origin"].data, d["step_col"].data, d["step_row"].data, d["tex_box"].data,
                     d["tex_layer"].data, d["layers"].data, centre.data, bbox.data, stex.data, counts.data)
    r_centre, r_bbox, r_tex, r_count = reference.project(
        s["coef"], first, s["band_tex"], s["band_origin"], s["step_col"], s["step_row"], s["tex_box"],
        s["tex_layer"], s["layers"], n)
    assert np.array_equal(centre.get(), r_centre)
    assert np.array_equal(bbox.get(), r_bbox) and np.array_equal(stex.get(), r_tex)
    assert np.array_equal(counts.get(), r_count)
    assert 0 < np.count_nonzero(r_count) < n  # the scene has both visible and culled splats

    assert set(s["tex_layer"][r_tex[r_count > 0], 0]) == {0, 1}  # both layers are drawn into
    tiles = TILES
    total = int(r_count.sum())
    textures = int(s["tex_layer"][:, 1].max()) + 1  # per layer
    r_ranges, r_vals = reference.bin_by_tile(r_bbox, r_tex, s["tex_layer"], s["layers"], tiles)
    r_records = reference.records(r_ranges, r_vals, first, r_centre, r_bbox, r_tex, s["values"], s["layers"], channels)
    for chunks in (1, 7, bin_chunks(n, tiles * textures, cc.info)):  # one, a few uneven, the renderer's
        chunk = -(-n // chunks)
        hist = cla.empty(q, (tiles * textures * chunks,), np.uint32)
        bin_args = (np.uint32(n), np.uint32(chunk), np.uint32(chunks), np.uint32(tiles), np.uint32(textures))
        inputs = (np.uint32(first), bbox.data, centre.data, stex.data, d["values"].data, d["tex_layer"].data,
                  d["layers"].data)
        ks.splat_chunk_tiles(q, (chunks,), None, *bin_args, np.int32(0), *inputs, hist.data, hist.data)
        r_hist = reference.count_tiles(r_bbox, r_tex, s["tex_layer"], s["layers"], textures, chunk, chunks,
                                       tiles)  # (chunks, runs)
        assert np.array_equal(hist.get(), r_hist.ravel())
        by_run, offsets = cla.empty_like(hist), cla.empty_like(hist)
        runs = np.uint32(tiles * textures)
        ks.transpose_counts(q, (hist.size,), None, np.uint32(chunks), runs, hist.data, by_run.data)
        assert np.array_equal(by_run.get(), r_hist.T.ravel())
        ExclusiveScanKernel(cc.ctx, np.uint32, "a+b", neutral="0")(by_run, offsets)
        r_offsets = np.concatenate([[0], np.cumsum(r_hist.T)[:-1]]).astype(np.uint32)
        assert np.array_equal(offsets.get(), r_offsets)
        ranges = cla.empty(q, (tiles, 2), np.uint32)
        ks.tile_ranges(q, (tiles,), None, np.uint32(tiles), np.uint32(textures), np.uint32(chunks), np.uint32(total),
                       offsets.data, ranges.data)
        assert np.array_equal(ranges.get(), r_ranges)
        cursors = cla.empty_like(hist)  # where each chunk writes next in each run, chunk-major
        ks.transpose_counts(q, (hist.size,), None, runs, np.uint32(chunks), offsets.data, cursors.data)
        assert np.array_equal(cursors.get(), r_offsets.reshape(-1, chunks).T.ravel())
        records = cla.empty(q, r_records.shape, np.uint32)
        ks.splat_chunk_tiles(q, (chunks,), None, *bin_args, np.int32(1), *inputs, cursors.data, records.data)
        assert np.array_equal(records.get(), r_records)

    local = 16 * 16 // px
    images = []
    for _ in range(2):  # accumulates onto what is there; a second run repeats the first bit for bit
        fb = cla.to_device(q, np.full((PIXELS, 4), 0.5, np.float32))
        ks.splat_accumulate(q, (TILES * local,), (local,), np.int32(len(LAYERS)), d["layers"].data,
                            ranges.data, records.data, d["tex_int"].data, d["tex_map"].data, d["texels"].data, fb.data)
        images.append(fb.get())
    assert np.array_equal(images[0], images[1])
    expected = 0.5 + reference.accumulate(r_ranges, r_vals, first, r_centre, r_bbox, r_tex, s["values"],
                                          s["textures"], s["layers"], channels)
    got = images[0]
    assert np.abs(expected - 0.5).max() > 1  # splats did land
    drawn = r_tex[r_count > 0]
    assert all(np.isin(drawn, np.flatnonzero(s["tex_int"][:, 3] == lookup)).sum() > 10 for lookup in LOOKUPS)
    # float32 sums of float32 texel coordinates: rounding at 1e-5 of the image's magnitude
    assert np.abs(got - expected).max() <= 1e-5 * np.abs(expected).max()
