"""The chunked model (docs/chunked.md): its coefficients, thresholded sets and files against the in-memory
model's, on odd shapes with chunkings that do not divide them."""

import io
import json
import os
import time

import dask.array as da
import h5py
import numpy as np
import pytest

import clwave
from clwave.errors import InputError
from clwave.model import chunked
from clwave.model.chunked import ChunkedWaveletVolume

# 3 x 3 x 3 chunks, the last of each axis cut short: a first, an inner and a last block per axis (no size needs more)
SHAPE, CHUNKS, SPACING = (21, 25, 19), (9, 11, 8), (1.5, 1.0, 0.75)


@pytest.fixture(autouse=True)
def small_blocks(monkeypatch):
    monkeypatch.setattr(chunked, "MIN_BLOCK_VOXELS", 0)  # many blocks on small volumes


def pair(rng, channels=1, zeros=0.3):
    """The same random volume in memory and chunked (exact ties in importance are then unlikely)."""
    shape = SHAPE + ((channels,) if channels > 1 else ())
    data = rng.random(shape, dtype=np.float32)
    data[rng.random(SHAPE) < zeros] = 0  # some empty voxels: zero coefficients and a content mask
    chunks = CHUNKS + ((channels,) if channels > 1 else ())
    return (clwave.Volume(data, spacing=SPACING, origin=(1, -2, 3)),
            clwave.Volume(da.from_array(data, chunks=chunks), spacing=SPACING, origin=(1, -2, 3)))


def assert_same(a: clwave.WaveletVolume, b: clwave.WaveletVolume):
    assert (a.shape, a.spacing, a.origin, a.levels, a.wavelets) == (b.shape, b.spacing, b.origin, b.levels, b.wavelets)
    for g, h in zip(a.groups, b.groups, strict=True):
        assert g.channels == h.channels
        assert (g.positions is None) == (h.positions is None)
        if g.positions is not None:
            assert np.array_equal(g.positions, h.positions)
        assert g.values.dtype == h.values.dtype and np.array_equal(g.values, h.values)
    assert np.array_equal(a.content_mask, b.content_mask)
    assert np.allclose(a.content, b.content)


@pytest.mark.parametrize("wavelet", ["haar", "linear", "quadratic", "cubic", "quintic"])
def test_chunked_transform_and_threshold_equal_the_in_memory_ones(rng, wavelet):
    vol, dvol = pair(rng)
    ref = clwave.WaveletVolume.from_volume(vol, wavelet, levels=2)
    model = clwave.WaveletVolume.from_volume(dvol, wavelet, levels=2)
    assert isinstance(model, ChunkedWaveletVolume)
    assert_same(ref, model.compute())  # every coefficient, bit for bit
    assert_same(ref.threshold(keep=0.07), model.threshold(keep=0.07).compute())


def test_keep_one_keeps_every_coefficient_in_memory_chunked_and_from_a_file(rng, tmp_path):
    # keep=1 kept as many coefficients as voxels, where a model has more (B-splines reach past the faces): not every
    # coefficient, as --keep's help says (offset17)
    vol, dvol = pair(rng)
    ref = clwave.WaveletVolume.from_volume(vol, "cubic", levels=1)
    live = int(np.count_nonzero(ref.groups[0].values[0]))
    assert live > vol.data.size  # more than the voxels: what keep=1 cut
    every = ref.threshold(keep=1)
    assert every.kept == live and np.abs(every.reconstruct().data - vol.data).max() < 1e-5  # perfect reconstruction
    assert_same(every, clwave.WaveletVolume.from_volume(dvol, "cubic", levels=1).threshold(keep=1).compute())
    every.save(tmp_path / "m.clw")
    assert_same(clwave.WaveletVolume.open(tmp_path / "m.clw", keep=1), clwave.WaveletVolume.open(tmp_path / "m.clw"))


def test_rgba_mixed_orders_focus_and_every_rule(rng):
    vol, dvol = pair(rng, channels=4)
    wavelets = ["cubic", "cubic", "cubic", "haar"]  # cubic colour, Haar opacity (paper Fig. 14)
    ref = clwave.WaveletVolume.from_volume(vol, wavelets, levels=2)
    model = clwave.WaveletVolume.from_volume(dvol, wavelets, levels=2)
    assert_same(ref, model.compute())
    n_approx = ref.groups[0].bands[0].size
    for kwargs in [dict(keep=n_approx / 2 / vol.data[..., 0].size),  # a cut inside the approximation
                   dict(keep=0.1, focus=((2.0, -1.0, 4.0), 6.0))]:
        assert_same(ref.threshold(**kwargs), model.threshold(**kwargs).compute())


def test_no_levels_and_one_block(rng, monkeypatch):
    vol, dvol = pair(rng)
    for levels in (0, 3):
        assert_same(clwave.WaveletVolume.from_volume(vol, "linear", levels=levels).threshold(keep=0.1),
                    clwave.WaveletVolume.from_volume(dvol, "linear", levels=levels).threshold(keep=0.1).compute())
    monkeypatch.setattr(chunked, "MIN_BLOCK_VOXELS", 1 << 30)  # the whole volume one block
    assert_same(clwave.WaveletVolume.from_volume(vol, "cubic", levels=2).threshold(threshold=0.2),
                clwave.WaveletVolume.from_volume(dvol, "cubic", levels=2).threshold(threshold=0.2).compute())


def test_on_a_local_cluster_of_two_worker_processes(rng, tmp_path):
    from distributed import Client, LocalCluster

    vol, dvol = pair(rng)
    ref = clwave.WaveletVolume.from_volume(vol, "cubic", levels=2).threshold(keep=0.05)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster, \
            Client(cluster) as client:
        model = clwave.WaveletVolume.from_volume(dvol, "cubic", levels=2, scheduler=client)
        assert_same(ref, model.threshold(keep=0.05).compute())
        model.threshold(keep=0.05).save(tmp_path / "m.clw")  # the client writes what the workers select
        assert client.status == "running"  # a client the caller gave stays open
    assert_same(ref, clwave.WaveletVolume.open(tmp_path / "m.clw"))


def test_classified_chunk_by_chunk_then_decomposed(tmp_path):
    import zarr

    vol = clwave.phantom("hydrogen", 24)
    zarr.create_array(tmp_path / "h.zarr", data=vol.data, chunks=(10, 7, 9))
    tf = clwave.TransferFunction.preset("hydrogen")
    chunked_rgba = tf.classify(clwave.load(tmp_path / "h.zarr"))
    assert chunked_rgba.chunked
    ref = clwave.WaveletVolume.from_volume(tf.classify(vol), "cubic", levels=2)  # (a symmetric phantom: ties)
    assert_same(ref, clwave.WaveletVolume.from_volume(chunked_rgba, "cubic", levels=2).compute())


def test_the_world_unit_goes_through_both_writers(tmp_path):
    """A volume's unit is the model's and its file's (the header's ``unit``) whether the file is written whole or a
    block at a time (docs/chunked.md §4), and comes back on reading; a model of a volume without one records none."""
    data = np.random.default_rng(5).random((12, 10, 8)).astype(np.float32)
    for chunks in (None, (6, 5, 4)):
        vol = clwave.Volume(data if chunks is None else da.from_array(data, chunks=chunks), unit="um")
        wv = clwave.WaveletVolume.from_volume(vol, "linear", levels=1).threshold(keep=0.5)
        assert wv.unit == "um" and vol.chunked == (chunks is not None)
        wv.save(tmp_path / "u.clw", overwrite=True)
        assert clwave.WaveletVolume.open(tmp_path / "u.clw").unit == "um"
        with h5py.File(tmp_path / "u.clw") as fh:
            assert json.loads(fh.attrs["header"])["unit"] == "um"
    clwave.WaveletVolume.from_volume(clwave.Volume(data), levels=1).save(tmp_path / "none.clw")
    assert clwave.WaveletVolume.open(tmp_path / "none.clw").unit is None
    assert clwave.WaveletVolume.open(tmp_path / "u.clw").reconstruct().unit == "um"
    with pytest.raises(InputError, match=r"^unit='inch' must be the world unit"):
        clwave.Volume(data, unit="inch")


def test_streamed_file_equals_the_in_memory_file(rng, tmp_path):
    vol, dvol = pair(rng, zeros=0.05)
    ref = clwave.WaveletVolume.from_volume(vol, "cubic", levels=2).threshold(keep=0.4)
    ref.save(tmp_path / "memory.clw")
    clwave.WaveletVolume.from_volume(dvol, "cubic", levels=2).threshold(keep=0.4).save(tmp_path / "chunked.clw")
    whole = clwave.WaveletVolume.open(tmp_path / "chunked.clw")
    assert_same(whole, clwave.WaveletVolume.open(tmp_path / "memory.clw"))
    assert_same(whole, ref)
    assert (tmp_path / "chunked.clw").read_bytes() == (tmp_path / "memory.clw").read_bytes()


def test_streamed_rgba_file_holds_the_in_memory_files_detail_field(rng, tmp_path):
    """The details' field energy (g<i>/detail_field, docs/chunked.md §4) of four channels in two groups of mixed
    orders, the blocks streamed in any order: the in-memory file's, bit for bit, and not zero."""
    vol, dvol = pair(rng, channels=4, zeros=0.05)
    wavelets = ["cubic", "cubic", "cubic", "linear"]
    clwave.WaveletVolume.from_volume(vol, wavelets, levels=2).threshold(keep=0.4).save(tmp_path / "memory.clw")
    clwave.WaveletVolume.from_volume(dvol, wavelets, levels=2).threshold(keep=0.4).save(tmp_path / "chunked.clw")
    with h5py.File(tmp_path / "memory.clw") as memory, h5py.File(tmp_path / "chunked.clw") as streamed:
        for gi in range(2):
            figure = memory[f"g{gi}/detail_field"][...]
            assert figure.shape == (2,) and np.all(figure > 0)
            assert np.array_equal(streamed[f"g{gi}/detail_field"][...], figure)


def test_streamed_file_in_many_runs_of_whole_chunks(rng, tmp_path, monkeypatch):
    from clwave.io import clw

    monkeypatch.setattr(clw, "ROWS", 64)  # tiers outgrow a chunk many times while blocks stream in
    vol, dvol = pair(rng, zeros=0.05)
    clwave.WaveletVolume.from_volume(dvol, "cubic", levels=2).threshold(keep=0.4).save(tmp_path / "chunked.clw")
    back = clwave.WaveletVolume.open(tmp_path / "chunked.clw")
    assert_same(back, clwave.WaveletVolume.from_volume(vol, "cubic", levels=2).threshold(keep=0.4))
    with h5py.File(tmp_path / "chunked.clw") as h5:
        runs = h5["g0/runs"][...]
    whole = runs[:, 2] % 64 == 0
    assert whole.sum() > 10 and (~whole).sum() <= len(np.unique(runs[:, 0]))  # one partial run a tier at most
    assert_same(clwave.WaveletVolume.open(tmp_path / "chunked.clw", keep=0.05), back.threshold(keep=0.05))


def test_prefix_reads_equal_thresholding_the_whole_file(rng, tmp_path, monkeypatch):
    data = rng.random((64, 72, 60), dtype=np.float32)  # 0.4 of it kept: some 110 000 coefficients, 7 chunks
    clwave.WaveletVolume.from_volume(data, "cubic", levels=2).threshold(keep=0.4).save(tmp_path / "m.clw")
    whole = clwave.WaveletVolume.open(tmp_path / "m.clw")

    read, handles = [], []
    opened = h5py.File

    class Counting(io.FileIO):
        def readinto(self, buffer):
            n = super().readinto(buffer)
            read[-1] += n
            return n

    def counting_file(path, mode="r", **kw):
        handles.append(Counting(path, "r"))
        return opened(handles[-1], mode, **kw)

    monkeypatch.setattr(h5py, "File", counting_file)
    size = (tmp_path / "m.clw").stat().st_size
    for keep in (0.01, 0.05, 0.2):
        read.append(0)
        prefix = clwave.WaveletVolume.open(tmp_path / "m.clw", keep=keep)
        assert_same(prefix, whole.threshold(keep=keep))  # which reads the content mask (when first used)
        while handles:
            handles.pop().close()
        assert read[-1] < (keep / 0.4 + 0.15) * size  # about that fraction (a chunk of 16 384 rows, metadata aside)


def test_bad_chunked_inputs(rng, monkeypatch):
    vol, dvol = pair(rng)
    with pytest.raises(InputError, match="scheduler= applies to a chunked volume"):
        clwave.WaveletVolume.from_volume(vol, "cubic", levels=2, scheduler=2)
    with pytest.raises(InputError, match="interpolate=True needs the whole volume"):
        clwave.WaveletVolume.from_volume(dvol, "cubic", levels=2, interpolate=True)
    data = dvol.data.copy()
    data[20, 20, 5] = np.nan
    with pytest.raises(InputError, match="non-finite"):  # found in the first pass, before any long work
        clwave.WaveletVolume.from_volume(clwave.Volume(data), "cubic", levels=2)
    huge = clwave.Volume(da.full((20, 20, 20), 3.0e38, chunks=10, dtype=np.float32))
    with pytest.raises(InputError, match="line integrals of this volume overflow float32"):  # a first-level block
        clwave.WaveletVolume.from_volume(huge, "cubic", levels=1).threshold(keep=0.1)  # task: its voxels, one line
    spiked = np.zeros((16, 16, 16), np.float32)
    spiked[4:8, 4:8, 4:8] = 1e37  # coefficients finite, line integrals not (1e37 x 2.77e3): refused as in memory
    for data in (spiked, da.from_array(spiked, chunks=8)):
        with pytest.raises(InputError, match="line integrals of this volume overflow float32"):
            clwave.WaveletVolume.from_volume(clwave.Volume(data, spacing=100.0), "cubic", levels=2).threshold(keep=0.1)
    with pytest.raises(InputError, match="line integrals of this volume overflow float32"):  # 0 levels: the voxels
        clwave.WaveletVolume.from_volume(huge, "cubic", levels=0).threshold(keep=0.1)
    with pytest.raises(InputError, match="thresholded already"):
        clwave.WaveletVolume.from_volume(dvol, "haar", levels=1).threshold(threshold=0.5).threshold(keep=0.1)
    with pytest.raises(InputError, match="not a Dask scheduler"):
        clwave.WaveletVolume.from_volume(dvol, scheduler="localhost")
    monkeypatch.setattr(clwave.schedulers, "CONNECT_TIMEOUT", "1s")
    start = time.perf_counter()
    with pytest.raises(InputError, match="no Dask scheduler answers at tcp://127.0.0.1:9"):
        clwave.WaveletVolume.from_volume(dvol, scheduler="tcp://127.0.0.1:9")
    assert time.perf_counter() - start < 10


def test_tiny_chunks_are_merged_into_bounded_blocks(monkeypatch):
    monkeypatch.setattr(chunked, "MAX_BLOCKS", 64)
    x = da.zeros((200, 190, 180, 1), chunks=(3, 5, 7, 1), dtype=np.float32)
    for halo in (0, 10):
        blocks = chunked._even_chunks(x, halo)
        assert np.prod(blocks.numblocks) <= 64
        for c in blocks.chunks[:3]:
            assert all(e % 2 == 0 for e in c[:-1]) and min(c) >= max(halo, 1)


def test_command_line_compresses_a_zarr_store_as_the_in_memory_path_does(rng, tmp_path, capsys):
    import zarr

    from clwave.cli import main

    data = rng.random((40, 36, 44), dtype=np.float32)
    np.save(tmp_path / "v.npy", data)
    zarr.create_array(tmp_path / "v.zarr", data=data, chunks=(16, 16, 16))
    assert main(["compress", str(tmp_path / "v.npy"), "--keep", "0.1", "-o", str(tmp_path / "memory.clw")]) == 0
    assert main(["compress", str(tmp_path / "v.zarr"), "--keep", "0.1", "-o", str(tmp_path / "chunked.clw")]) == 0
    out = capsys.readouterr().out
    assert "not measured: the input was read chunk by chunk" in out and "6,336 coefficients" in out
    assert_same(clwave.WaveletVolume.open(tmp_path / "memory.clw"), clwave.WaveletVolume.open(tmp_path / "chunked.clw"))
    assert main(["render", str(tmp_path / "chunked.clw"), "--keep", "0.02", "--size", "32",
                 "-o", str(tmp_path / "x.png")]) == 0  # reads a prefix of the file
    assert (tmp_path / "x.png").exists()


@pytest.mark.parametrize("argv, needle", [
    (["--workers", "0"], "--workers 0 must be from 1"),
    (["--scheduler", "localhost"], "--scheduler localhost is not an address"),
    (["--chunks", "x"], "--chunks x must be auto, off or a chunk edge"),
    (["--interpolate"], "--interpolate needs the whole volume in memory"),
    (["--workers", "2", "--chunks", "off"], "--workers and --scheduler apply to a chunked input"),
])
def test_command_line_refuses_bad_chunked_options(rng, tmp_path, capsys, argv, needle):
    import zarr

    from clwave.cli import main

    zarr.create_array(tmp_path / "v.zarr", data=rng.random((20, 20, 20), dtype=np.float32), chunks=(8, 8, 8))
    assert main(["compress", str(tmp_path / "v.zarr"), *argv, "-o", str(tmp_path / "x.clw")]) == 2
    err = capsys.readouterr().err
    assert needle in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.clw").exists()


def test_ties_at_the_cut_go_to_the_lowest_positions_whatever_the_block_order(rng):
    # a piecewise-constant volume (a checkerboard of 4-voxel cubes): classes of equal importances
    data = ((np.indices(SHAPE) // 4).sum(axis=0) % 2).astype(np.float32)
    vol, dvol = clwave.Volume(data), clwave.Volume(da.from_array(data, chunks=CHUNKS))
    full = clwave.WaveletVolume.from_volume(vol, "cubic", levels=2)
    keep = 0.38  # the cut falls in a class of 26 equal importances, and keeps 11 of them
    ref = full.threshold(keep=keep)
    g = full.groups[0]
    imp = full.importance(g)
    live = np.flatnonzero(np.any(g.values != 0, axis=0))
    detail = live[live >= g.band_slices()[0].stop]
    take = int(round(keep * data.size)) - (len(live) - len(detail))
    # the oracle: importance descending, then position ascending
    expected = np.sort(detail[np.lexsort((detail, -imp[detail]))[:take]])
    cut = imp[expected].min()
    assert np.count_nonzero(imp[detail] == cut) > np.count_nonzero(imp[expected] == cut) > 0  # a tie split by the cut
    kept = np.setdiff1d(ref.groups[0].positions, live[live < g.band_slices()[0].stop])
    assert np.array_equal(kept, g.all_positions()[expected])
    model = clwave.WaveletVolume.from_volume(dvol, "cubic", levels=2)
    for _ in range(3):  # the blocks' results arrive in the order the threads finish them
        assert_same(ref, model.threshold(keep=keep).compute())


def test_chunked_inputs_get_the_hints_of_a_volume_read_whole(tmp_path, capsys):
    """The HU hint (from the faces' chunks) and the --keep warning (from the histogram pass, before the selection)
    say on a Zarr store and an HDF5 file what they say on the same volume read whole (docs/chunked.md §3,
    docs/coordinates.md §1); a chunked compression with no reason for either prints nothing on stderr."""
    import warnings

    import zarr

    from clwave.cli import main
    from clwave.errors import ClwaveWarning

    ct = np.full((22, 26, 18), -1000.0, np.float32)  # air about soft tissue and bone, in HU
    ct[4:18, 6:20, 4:14], ct[8:12, 10:14, 7:11] = 40.0, 1200.0
    np.save(tmp_path / "ct.npy", ct)
    zarr.create_array(tmp_path / "ct.zarr", data=ct, chunks=(8, 8, 8))
    with h5py.File(tmp_path / "ct.h5", "w") as fh:
        fh.create_dataset("ct", data=ct, chunks=(7, 9, 5))
    zarr.create_array(tmp_path / "mu.zarr", data=ct + 1000, chunks=(8, 8, 8))  # air at 0: no reason for a hint

    def compress(source, *extra):
        code = main(["compress", str(tmp_path / source), "--levels", "2", *extra, "-o", str(tmp_path / "o.clw"),
                     "--force"])
        return code, capsys.readouterr().err

    code, whole = compress("ct.npy", "--keep", "0.005")
    hu, keep = whole.splitlines()
    assert code == 0 and "looks like CT in Hounsfield units" in hu and "--hu-to-mu" in hu
    memory = clwave.WaveletVolume.from_volume(clwave.load(tmp_path / "ct.npy"), levels=2).groups[0]
    band = int(np.count_nonzero(memory.values[:, :memory.band_slices()[0].stop]))  # live approximation coefficients
    assert f"keeps {round(0.005 * ct.size):,} coefficients, fewer than the {band:,} of the approximation" in keep
    for source, chunks in (("ct.zarr", []), ("ct.h5", []), ("ct.npy", ["--chunks", "8"])):
        code, err = compress(source, "--keep", "0.005", *chunks)
        assert code == 0 and err == whole.replace("ct.npy", source), err
        code, err = compress(source, "--keep", "0.005", "--subtract", "-1000", *chunks)  # the hint's fix: it is gone
        assert code == 0 and "Hounsfield" not in err, err
    least = keep.rsplit("--keep ", 1)[1].split()[0]
    for source, extra in (("mu.zarr", ["--keep", least]), ("mu.zarr", []), ("ct.zarr", ["--hu-to-mu"])):
        code, err = compress(source, *extra)
        assert code == 0 and err == "", (source, extra, err)
    model = clwave.WaveletVolume.from_volume(clwave.load(tmp_path / "ct.zarr"), levels=2)
    assert model.volume.chunked
    with pytest.warns(ClwaveWarning, match=rf"keep=0.005 keeps {round(0.005 * ct.size):,} coefficients, fewer than "
                                           rf"the {band:,} of the approximation band: .*; keep={least} or more"):
        model.threshold(keep=0.005)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ClwaveWarning)
        model.threshold(keep=float(least))


def test_a_chunked_model_given_to_a_renderer_is_told_to_be_saved_and_opened():
    """splat/raytrace take an in-memory model: a chunked one is refused in one line naming save and open."""
    x = da.from_array(np.random.default_rng(0).random((16, 16, 16), np.float32), chunks=8)
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(x), levels=1)
    assert isinstance(wv, ChunkedWaveletVolume)
    for render in (clwave.splat, clwave.raytrace):
        for cluster in ({}, {"scheduler": "tcp://127.0.0.1:1"}):  # refused before any cluster is reached, too
            refusal = r"got clwave.ChunkedWaveletVolume: save it .*WaveletVolume.open"
            with pytest.raises(InputError, match=refusal) as err:
                render(wv, clwave.Camera(), **cluster)
            assert "\n" not in str(err.value)


def _damage_zarr(path):
    chunk = sorted(p for p in (path / "c").rglob("*") if p.is_file())[5]
    with open(chunk, "r+b") as fh:
        fh.seek(10)
        fh.write(b"\xff" * 20)  # its Zstandard frame no longer decodes


def _damage_hdf5(path):
    with h5py.File(path) as fh:
        info = fh["v"].id.get_chunk_info(5)
    with open(path, "r+b") as fh:
        fh.seek(info.byte_offset + 4)
        fh.write(b"\xff" * 20)  # its deflate stream no longer inflates


def _cut_npy(path):
    with open(path, "r+b") as fh:
        fh.truncate(path.stat().st_size // 2)  # the memory map of the later chunks fails


@pytest.mark.parametrize("name, damage", [("v.zarr", _damage_zarr), ("v.h5", _damage_hdf5), ("v.npy", _cut_npy)])
def test_a_chunk_that_cannot_be_read_mid_way_is_one_line_and_no_file(rng, tmp_path, capsys, name, damage):
    """A chunk damaged (or a file cut) after the content pass read it: the selection pass that reads it again stops
    with the one-line FileFormatError a whole read gives, naming the file, and leaves no .clw (the one there kept);
    on the command line (which finds the cut .npy at its open), one line and exit code 2 (was: the library's own
    exception, 'internal error ... a bug in clwave', exit code 1)."""
    import zarr

    from clwave.cli import main
    from clwave.errors import FileFormatError

    data = rng.random((24, 26, 28), dtype=np.float32)
    source = tmp_path / name
    if name.endswith(".zarr"):
        zarr.create_array(source, data=data, chunks=(8, 8, 8))
    elif name.endswith(".h5"):
        with h5py.File(source, "w") as fh:
            fh.create_dataset("v", data=data, chunks=(8, 8, 8), compression="gzip")
    else:
        np.save(source, data)
    model = clwave.WaveletVolume.from_volume(clwave.load(source, chunks=8), levels=2).threshold(threshold=0.1)
    damage(source)
    (tmp_path / "o.clw").write_bytes(b"old")
    with pytest.raises(FileFormatError, match=rf"^cannot read {source}.*the file may be truncated or corrupt$") as err:
        model.save(tmp_path / "o.clw", overwrite=True)
    assert "\n" not in str(err.value)
    assert (tmp_path / "o.clw").read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([name, "o.clw"])  # no temporary file left
    assert main(["compress", str(source), "--chunks", "8", "--levels", "2", "-o", str(tmp_path / "x.clw")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("clwave: error: ") and str(source) in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "x.clw").exists()


class _DiesInAWorker:
    """An array whose chunks a Dask worker process cannot read: reading one there ends the process, as the kernel
    ends a worker out of memory."""

    def __init__(self, data):
        self.data, self.parent = data, os.getpid()
        self.shape, self.dtype, self.ndim = data.shape, data.dtype, data.ndim

    def __getitem__(self, index):
        if os.getpid() != self.parent:
            os._exit(1)
        return self.data[index]


def test_workers_that_die_end_the_work_in_one_line(rng, tmp_path, capfd):
    """Every worker that takes a task dies (Dask gives up after four): a WorkerLostError line naming fewer workers
    and smaller chunks, the command line's words too, and no .clw (was: distributed's KilledWorker, which the command
    line called an internal error, a bug of clwave; then, results waited for in block order, a wait for ever on a
    block no worker was left to run, two runs in three)."""
    from clwave.errors import WorkerLostError

    data = da.from_array(_DiesInAWorker(rng.random((16, 18, 20), dtype=np.float32)), chunks=8,
                         meta=np.empty((0, 0, 0), np.float32))
    model = clwave.WaveletVolume.from_volume(clwave.Volume(data), levels=1).threshold(threshold=0.1)  # on threads
    model.scheduler = 2  # two worker processes
    with pytest.raises(WorkerLostError, match=r"the Dask workers died .*give fewer workers \(each has a share of "
                                              r"the memory\) or smaller chunks") as err:
        model.save(tmp_path / "o.clw")
    cli = "give fewer --workers (each has a share of the memory) or a smaller --chunks edge"
    assert "\n" not in str(err.value) and cli in err.value.cli_message() and "logs" not in str(err.value)
    assert list(tmp_path.iterdir()) == []
    assert capfd.readouterr().err == ""  # nor the workers' logs of their lost connections


def test_worker_processes_log_nothing_of_a_failed_task(rng, tmp_path, capfd):
    """A task that fails in a worker process of scheduler=N (a damaged chunk) is raised here, in one line: the
    workers' own logs stay quiet (were: 'distributed.worker - ERROR - Compute Failed' and the task on stderr)."""
    import zarr

    from clwave.errors import FileFormatError

    zarr.create_array(tmp_path / "v.zarr", data=rng.random((24, 26, 28), dtype=np.float32), chunks=(8, 8, 8))
    _damage_zarr(tmp_path / "v.zarr")
    capfd.readouterr()
    with pytest.raises(FileFormatError, match="cannot read"):
        clwave.WaveletVolume.from_volume(clwave.load(tmp_path / "v.zarr", chunks=8), levels=2, scheduler=2)
    assert capfd.readouterr().err == ""


def test_values_beyond_float32_are_refused_alike_with_no_numpy_warning():
    """float64 voxels beyond float32's range: the chunked volume gives the in-memory volume's one InputError line and,
    as it, no NumPy 'overflow encountered in cast' RuntimeWarning (which Dask's astype printed, once a process)."""
    import warnings

    data = np.ones((8, 8, 8))
    data[3, 3, 3] = 1e39
    for source in (data, da.from_array(data, chunks=4)):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with pytest.raises(InputError, match="1 non-finite voxel value.*beyond float32's range"):
                clwave.WaveletVolume.from_volume(clwave.Volume(source), levels=1)


def test_a_scheduler_address_without_workers_is_one_line_then_with_one_the_in_memory_model(rng, monkeypatch):
    """scheduler="tcp://..." of a scheduler that has no workers: one InputError line naming `dask worker`, after
    CONNECT_TIMEOUT (was: the work submitted and waiting for ever); once a worker joins, the model equals the
    in-memory one."""
    from distributed import LocalCluster

    monkeypatch.setattr(clwave.schedulers, "CONNECT_TIMEOUT", "1s")
    vol, dvol = pair(rng)
    with LocalCluster(n_workers=0, processes=False, dashboard_address=":0") as cluster:
        address = cluster.scheduler_address
        start = time.perf_counter()
        with pytest.raises(InputError, match=rf"^the Dask scheduler at {address} has no workers .*`dask worker "):
            clwave.WaveletVolume.from_volume(dvol, "cubic", levels=2, scheduler=address)
        assert time.perf_counter() - start < 10
        cluster.scale(1)
        cluster.wait_for_workers(1, timeout=60)  # scale() only asks for it: joined, not left to the 1 s timeout
        model = clwave.WaveletVolume.from_volume(dvol, "cubic", levels=2, scheduler=address).threshold(keep=0.05)
        assert_same(clwave.WaveletVolume.from_volume(vol, "cubic", levels=2).threshold(keep=0.05), model.compute())
