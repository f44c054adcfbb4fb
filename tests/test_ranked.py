"""What a SplatRenderer holds of a model (docs/splatting.md §6, docs/viewer.md §2): its packed tables, their
energy and order against NumPy oracles, made in blocks; each coefficient held once (on a device that shares the
host's memory the device arrays are the tables); passes of at most PASS_ROWS coefficients; and the peak host memory
of ranking, per coefficient."""

import tracemalloc

import numpy as np
import pyopencl as cl
import pytest
import scipy.ndimage

import clwave
from clwave.model import ranking
from clwave.model.ranking import by_importance
from clwave.splat import accumulator, ranked
from clwave.splat.ranked import ENERGY_STEP, on_device, ranked_groups
from clwave.view.prefix import prefix_first

BLOCK = 2 * ENERGY_STEP  # rows a block in these tests: several blocks, and energy marks in each


@pytest.fixture(scope="module")
def wv():
    """Random RGBA 40^3, colour cubic and opacity linear (two groups: 3 channels and 1), 2 levels, 60 % kept."""
    data = np.random.default_rng(5).random((40, 40, 40, 4)).astype(np.float32)
    return clwave.WaveletVolume.from_volume(clwave.Volume(data), ["cubic"] * 3 + ["linear"], levels=2).threshold(
        keep=0.6)


def oracle(wv, g):
    """A group's ranking by a lexsort (decreasing importance, then position), each band's ``np.unravel_index``, and
    the cumulative energy as one np.cumsum of each coefficient's float64 sum over channels."""
    positions, importance = g.all_positions(), wv.importance(g)
    order = np.lexsort((positions, -importance))
    starts = np.array([b.start for b in g.bands])
    band = np.searchsorted(starts, positions[order], side="right") - 1
    index = np.array([np.unravel_index(p - g.bands[b].start, g.bands[b].shape) for p, b in zip(positions[order], band)])
    values = g.values[:, order].T
    energy = np.zeros(len(order))
    for channel in values.T:
        energy += np.square(channel, dtype=np.float64)
    return order, band, index, values, np.cumsum(energy)


def test_packed_tables_are_the_ranking_made_in_blocks(wv, monkeypatch):
    monkeypatch.setattr(ranking, "RANK_ROWS", BLOCK)
    groups = ranked_groups(wv)
    for g, group in zip(wv.groups, groups):
        order, band, index, values, energy = oracle(wv, g)
        table, n = group["table"], len(order)
        assert n > 3 * BLOCK and group["count"] == n and group["channels"] == len(g.channels)
        assert np.array_equal(table.coef[:, :3], index[:, ::-1]) and np.array_equal(table.index, index)
        assert np.array_equal(table.band, [g.bands[b].level * 8 + g.bands[b].code for b in band])
        assert np.array_equal(table.values, values) and not table.packed[:, len(g.channels):].any()
        present = {(g.bands[b].level, g.bands[b].key): int(np.argmax(band == b)) for b in np.unique(band)}
        assert group["present"] == present
        got = group["energy"]  # every coefficient's, and from the end
        assert len(got) == n and np.array_equal(np.asarray(got), energy)
        assert [got[i] for i in range(n)] == list(energy) and got[-1] == energy[-1] and got[-n] == energy[0]
        with pytest.raises(IndexError):
            got[n]
        assert len(got.marks) == n // ENERGY_STEP  # what it holds: a sum every ENERGY_STEP coefficients


def test_by_importance_puts_the_first_rows_first_each_part_by_importance(wv):
    """``first`` rows by decreasing importance, then the others, ties by position (a lexsort oracle), on importances
    with ties (rounded to a few values)."""
    importance = np.round(wv.importance(wv.groups[0]) * 4) / 4
    n = len(importance)
    first = np.sort(np.random.default_rng(1).choice(n, n // 5, replace=False))
    rest = np.ones(n, bool)
    rest[first] = False
    got = by_importance(importance, first=first)
    assert got.dtype == np.uint32 and len(np.unique(importance)) < n / 100
    assert np.array_equal(got, np.lexsort((np.arange(n), -importance, rest)))
    assert np.array_equal(by_importance(importance), np.lexsort((np.arange(n), -importance)))


def test_prefix_first_is_the_prefix_then_the_rest(wv):
    part = wv.threshold(keep=0.1)
    for g, p, order in zip(wv.groups, part.groups, prefix_first(wv, part)):
        positions = g.all_positions()
        head = positions[order[:p.kept]]
        assert np.array_equal(np.sort(head), p.all_positions())
        assert np.array_equal(head, p.all_positions()[by_importance(part.importance(p))])
        assert np.array_equal(np.sort(order), np.arange(g.kept))
        importance = wv.importance(g)[order[p.kept:]]
        assert np.all(np.diff(importance) <= 0)


def test_on_a_device_sharing_the_hosts_memory_the_device_arrays_are_the_tables(cc, wv, monkeypatch):
    """No second copy of a model's coefficients where device memory is host memory (PoCL); a copy elsewhere: both
    hold the table (read back)."""
    table = ranked_groups(wv)[0]["table"]
    for shares in (True, False):
        monkeypatch.setattr(ranked, "_shares_host_memory", lambda device, shares=shares: shares)
        coef, values = on_device(cc, table)
        assert np.array_equal(coef.get(), table.coef) and np.array_equal(values.get(), table.packed)
        assert all(bool(a.data.flags & cl.mem_flags.USE_HOST_PTR) == shares for a in (coef, values))
        if shares:
            assert [a.data.get_host_array(a.shape, a.dtype).ctypes.data for a in (coef, values)] == [
                table.coef.ctypes.data, table.packed.ctypes.data]


def test_a_renderers_passes_hold_at_most_pass_rows(cc, wv, monkeypatch):
    """Every coefficient on the device, splatted PASS_ROWS at a time: per-splat buffers of PASS_ROWS, the same
    counts, and the image the one pass's in another float32 grouping of its terms (within 1e-5 of its maximum, the
    bound of test_splat_memory's regrouping); with coarse framebuffers in perspective (its plan projected a pass at
    a time), the same splats dropped."""
    data = scipy.ndimage.gaussian_filter(np.random.default_rng(2).random((16, 16, 16)), 2.0).astype(np.float32)
    smooth = clwave.WaveletVolume.from_volume(clwave.Volume(data), wavelet="cubic", levels=2)
    cone = clwave.ConeBeam(60.0, 90.0, 32, pixel=1.6, azimuth=0, elevation=0)
    cases = [(wv, clwave.Camera(30, 20, 32), None), (smooth, cone, 2e-2)]
    for model, camera, coarse in cases:
        one = clwave.SplatRenderer(model, device=cc, coarse=coarse).render(camera)
        monkeypatch.setattr(accumulator, "PASS_ROWS", 1000)  # the passes' and their buffers' one home
        r = clwave.SplatRenderer(model, device=cc, coarse=coarse)
        passes = r.render(camera)
        monkeypatch.undo()
        assert model.kept > 3 * 1000 and len(r._work["bbox"]) == 1000 and passes.meta["chunk_coefficients"] is None
        for key in ("coefficients", "tile_pairs", "pixel_updates"):
            assert passes.meta[key] == one.meta[key], key
        if coarse:  # the same splats dropped; their bound, of the image maximum, to its float32 rounding
            got, want = (dict(m.meta["dropped"]) for m in (passes, one))
            assert got.pop("bound") == pytest.approx(want.pop("bound"), rel=1e-5) and got == want
            assert want["splats"] > 0
        assert np.abs(passes.image - one.image).max() <= 1e-5 * np.abs(one.image).max()


def test_ranking_takes_at_most_these_bytes_a_coefficient(wv, monkeypatch):
    """The host memory ranking makes at its peak (NumPy's arrays, traced), beside the model, per coefficient of the
    largest group (K) and of them all (T): the prefix's order 16 K (the importance, the sort's keys and the order)
    and 4 T (the orders made), with 48 bytes a coefficient of the prefix (its rows, importance and values); the
    renderer's tables 32 T (the packed tables) and 4 K (an order), with a block's work arrays (about 80 bytes a row)
    besides."""
    monkeypatch.setattr(ranking, "RANK_ROWS", BLOCK)
    part = wv.threshold(keep=0.1)
    most, total = max(g.kept for g in wv.groups), sum(g.kept for g in wv.groups)
    slack = 64 * 1024 + 128 * BLOCK
    for run, bound in ((lambda: prefix_first(wv, part), 16 * most + 4 * total + 48 * part.kept),
                       (lambda: ranked_groups(wv), 4 * most + 32 * total)):
        run()  # warm: any cache of the model made
        tracemalloc.start()
        try:
            run()
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert most > 10 * BLOCK and peak <= bound + slack, (peak / total, bound / total)
