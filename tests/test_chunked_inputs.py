"""Chunked inputs (docs/chunked.md §1): Zarr, OME-Zarr and HDF5 stores and memory-mapped .npy/.raw/.nii
read as Dask arrays equal the in-memory load; chunked classification equals the in-memory one bit for
bit; tools/make_zarr.py writes phantom() chunk by chunk; bad stores give one-line errors."""

import importlib.util
import json
from pathlib import Path

import dask.array as da
import h5py
import nibabel as nib
import numpy as np
import pytest
import zarr

from clwave.cli import main
from clwave.errors import ClwaveError, FileFormatError, InputError
from clwave.io import loaders
from clwave.io.loaders import shared
from clwave.io.loaders import load
from clwave.io.phantoms import NAMES, phantom, phantom_block
from clwave.model import tf_passes
from clwave.model.transfer import TransferFunction
from clwave.model.volume import Volume

SHAPE = (9, 10, 11)


@pytest.fixture
def volume(rng):
    return rng.integers(-1000, 3000, SHAPE).astype(np.int16)


def one_line(excinfo, *words):
    message = str(excinfo.value)
    assert isinstance(excinfo.value, ClwaveError) and "\n" not in message
    for word in words:
        assert word in message, message
    return message


# --------------------------------------------------------------------------- every reader, chunked == whole

def _npy(tmp_path, a):
    np.save(tmp_path / "v.npy", a)
    return tmp_path / "v.npy", {}


def _npy_fortran(tmp_path, a):
    np.save(tmp_path / "v.npy", np.asfortranarray(a))
    return tmp_path / "v.npy", {}


def _raw(tmp_path, a):
    a.astype(">i2").tofile(tmp_path / "v.raw")
    return tmp_path / "v.raw", dict(shape=a.shape, dtype="int16", byte_order=">")


def _nifti(tmp_path, a):
    # axes permuted and flipped against RAS, with a scale slope: the chunked path reorients lazily
    affine = np.array([[0, 0, -2.0, 10], [0, 1.5, 0, -5], [0.5, 0, 0, 3], [0, 0, 0, 1]])
    image = nib.Nifti1Image(a, affine)
    image.header.set_slope_inter(0.5, -3.0)
    nib.save(image, tmp_path / "v.nii")
    return tmp_path / "v.nii", {}


def _zarr(fmt):
    def write(tmp_path, a):
        zarr.create_array(tmp_path / "v.zarr", data=a, chunks=(4, 3, 5), zarr_format=fmt)
        return tmp_path / "v.zarr", {}
    return write


def _zarr_in_group(tmp_path, a):
    group = zarr.open_group(tmp_path / "g.zarr", mode="w")
    group.create_group("scans").create_array("ct", data=a, chunks=(4, 4, 4))
    group.create_array("mask", data=np.zeros(a.shape, np.uint8))
    return f"{tmp_path / 'g.zarr'}:/scans/ct", {}


def _hdf5(tmp_path, a):
    with h5py.File(tmp_path / "v.h5", "w") as fh:
        fh.create_dataset("only", data=a, chunks=(3, 5, 4))
        fh["labels"] = np.arange(5)        # not 3-D/4-D: ignored when picking the only volume
    return tmp_path / "v.h5", {}


def _hdf5_path(tmp_path, a):
    with h5py.File(tmp_path / "v.hdf5", "w") as fh:
        fh["group/ct"] = a
        fh["group/other"] = a + 1
    return f"{tmp_path / 'v.hdf5'}:/group/ct", {}


READERS = {"npy": _npy, "npy-fortran": _npy_fortran, "raw": _raw, "nifti": _nifti, "zarr-v2": _zarr(2),
           "zarr-v3": _zarr(3), "zarr-group-path": _zarr_in_group, "hdf5": _hdf5, "hdf5-path": _hdf5_path}


@pytest.mark.parametrize("write", READERS.values(), ids=READERS.keys())
def test_every_reader_chunked_equals_whole(tmp_path, volume, write):
    path, options = write(tmp_path, volume)
    whole = load(path, chunks=False, **options)
    for chunks in (4, "auto"):
        vol = load(path, chunks=chunks, **options)
        assert vol.chunked and vol.data.dtype == np.float32
        if chunks == 4:  # cubes of edge 4, which do not divide the shape
            assert {c for axis in vol.data.chunks for c in axis} <= {1, 2, 3, 4}
        np.testing.assert_array_equal(vol.data.compute(), whole.data)
        assert (vol.spacing, vol.origin) == (whole.spacing, whole.origin)
    if write is not _nifti:
        np.testing.assert_array_equal(whole.data, volume)


def test_nifti_chunked_geometry_is_the_in_memory_geometry(tmp_path, volume):
    path, _ = _nifti(tmp_path, volume)
    vol = load(path, chunks=4)
    # RAS+: z from the first axis (0.5 mm), y from the second (1.5), x from the third, flipped (2)
    assert vol.shape == SHAPE and vol.spacing == (0.5, 1.5, 2.0)
    np.testing.assert_array_equal(vol.data.compute(), (volume * 0.5 - 3.0)[:, :, ::-1].astype(np.float32))


def test_the_rule_chunked_or_whole(tmp_path, volume, monkeypatch):
    np.save(tmp_path / "v.npy", volume)
    _zarr(3)(tmp_path, volume)
    _hdf5(tmp_path, volume)
    assert not load(tmp_path / "v.npy").chunked                       # small files: in memory, as ever
    assert load(tmp_path / "v.zarr").chunked and load(tmp_path / "v.h5").chunked    # stores: always chunked
    assert not load(tmp_path / "v.zarr", chunks=False).chunked
    monkeypatch.setattr(shared, "CHUNKED_MIN_BYTES", volume.size * 4)
    assert load(tmp_path / "v.npy").chunked                           # as big as the threshold: chunked
    # chunks="auto": whole multiples of the store's own chunks (3, 5, 4), up to CHUNK_BYTES of float32
    assert load(tmp_path / "v.h5").data.chunks == ((9,), (10,), (11,))
    monkeypatch.setattr(shared, "CHUNK_BYTES", 3 * 5 * 4 * 4 * 2)
    chunks = load(tmp_path / "v.h5").data.chunks
    assert 1 < np.prod([c[0] for c in chunks]) <= 120
    assert all(c % own == 0 for axis, own in zip(chunks, (3, 5, 4)) for c in axis[:-1])
    monkeypatch.setattr(shared, "CHUNK_BYTES", 100)     # store chunks bigger than that: one each, never cut
    assert [axis[0] for axis in load(tmp_path / "v.h5").data.chunks] == [3, 5, 4]


def test_hu_to_mu_and_subtract_apply_per_chunk(tmp_path, volume):
    np.save(tmp_path / "ct.npy", volume)
    options = dict(hu_to_mu=True, mu_water=0.02, subtract=0.001)
    np.testing.assert_array_equal(load(tmp_path / "ct.npy", chunks=4, **options).data.compute(),
                                  load(tmp_path / "ct.npy", **options).data)


def test_non_finite_and_huge_values_are_refused_when_the_chunk_is_read(tmp_path):
    data = np.zeros((8, 8, 8))
    data[7, 7, 7] = np.nan
    np.save(tmp_path / "nan.npy", data)
    vol = load(tmp_path / "nan.npy", chunks=4)                  # nothing read yet
    vol.data[:4].compute()                                      # the clean chunks read fine
    with pytest.raises(InputError) as excinfo:
        vol.data.compute()
    one_line(excinfo, "NaN")
    data[7, 7, 7] = 1e300
    np.save(tmp_path / "huge.npy", data)
    vol = load(tmp_path / "huge.npy", chunks=4)
    with pytest.raises(InputError) as excinfo:
        vol.data.sum().compute()
    one_line(excinfo, "float32's range")


@pytest.mark.parametrize("text, expected", [
    ("C:\\data\\scan.h5:/volumes/ct", ("C:\\data\\scan.h5", "volumes/ct")),
    ("/a:b/scan.hdf5:ct", ("/a:b/scan.hdf5", "ct")),
    ("x.h5:/y.h5:/z", ("x.h5:/y.h5", "z")),        # the last ':' after such a suffix
    ("store.zarr:/0", ("store.zarr", "0")),
    ("C:\\data\\scan.npy", ("C:\\data\\scan.npy", None)),
])
def test_inner_paths_split_at_the_last_colon_after_a_store_suffix(text, expected):
    path, inner = loaders._split_inner(text)
    assert (str(path), inner) == (str(Path(expected[0])), expected[1])


# --------------------------------------------------------------------------- OME-Zarr

def _ome(tmp_path, name="img.zarr", fmt=2, axes=("t", "c", "z", "y", "x"), levels=None, image_scale=None,
         **image):
    """An OME-Zarr image: level 0 of shape (1, 2, 4, 5, 6), level 1 (1, 2, 2, 3, 3)."""
    rng = np.random.default_rng(7)
    group = zarr.open_group(tmp_path / name, mode="w", zarr_format=fmt)
    arrays = {"0": rng.integers(0, 255, (1, 2, 4, 5, 6)).astype(np.uint8),
              "1": rng.integers(0, 255, (1, 2, 2, 3, 3)).astype(np.uint8)}
    for path, a in arrays.items():
        group.create_array(path, data=a, chunks=(1, 1, 3, 2, 4))
    if levels is None:
        levels = [{"path": "0", "coordinateTransformations": [
                      {"type": "scale", "scale": [1, 1, 2.0, 0.5, 0.25]},
                      {"type": "translation", "translation": [0, 0, 10.0, 20.0, 30.0]}]},
                  {"path": "1", "coordinateTransformations": [
                      {"type": "scale", "scale": [1, 1, 4.0, 1.0, 0.5]},
                      {"type": "translation", "translation": [0, 0, 11.0, 20.25, 30.125]}]}]
    multiscale = {"axes": [{"name": a, "type": {"t": "time", "c": "channel"}.get(a, "space")} for a in axes],
                  "datasets": levels, **image}
    multiscale["coordinateTransformations"] = image_scale or [{"type": "scale", "scale": [1, 1, 1, 1, 2.0]}]
    if fmt == 2:
        group.attrs["multiscales"] = [{"version": "0.4", **multiscale}]
    else:
        group.attrs["ome"] = {"version": "0.5", "multiscales": [multiscale]}
    return tmp_path / name, arrays


@pytest.mark.parametrize("fmt", [2, 3])
def test_ome_zarr_spacing_origin_and_channels(tmp_path, fmt):
    path, arrays = _ome(tmp_path, fmt=fmt)
    vol = load(path)
    assert vol.chunked and vol.shape == (4, 5, 6) and vol.channels == 2
    np.testing.assert_array_equal(vol.data.compute(), arrays["0"][0].transpose(1, 2, 3, 0))
    # x: scale 0.25 then the image's 2 -> 0.5; first voxel at 30 * 2 = 60, centre 60 + 0.5 * (6 - 1) / 2
    # y: 0.5, first voxel at 20, centre 20 + 0.5 * (5 - 1) / 2; z: 2, first at 10, centre 10 + 2 * (4 - 1) / 2
    assert vol.spacing == (2.0, 0.5, 0.5)
    assert vol.origin == (61.25, 21.0, 13.0)
    level1 = load(path, level=1, chunks=False)
    np.testing.assert_array_equal(level1.data, arrays["1"][0].transpose(1, 2, 3, 0))
    # x: 0.5 * 2 = 1, first at 30.125 * 2 = 60.25, centre 60.25 + 1; y: 1, 20.25 + 1; z: 4, 11 + 4 / 2
    assert level1.spacing == (4.0, 1.0, 1.0) and level1.origin == (61.25, 21.25, 13.0)


def test_ome_zarr_units_are_converted_to_the_x_axis_unit(tmp_path):
    path, _ = _ome(tmp_path, fmt=2, axes=("t", "c", "z", "y", "x"))
    attrs = zarr.open_group(path, mode="r+").attrs
    multiscales = attrs["multiscales"]
    for axis, unit in zip(multiscales[0]["axes"][2:], ("micrometer", "nanometer", "nanometer")):
        axis["unit"] = unit
    attrs["multiscales"] = multiscales
    vol = load(path)
    assert vol.spacing == (2000.0, 0.5, 0.5) and vol.origin == (61.25, 21.0, 13000.0)
    assert vol.unit == "nm"  # the x axis's, the spacing's (was None: no OME-Zarr had a unit)


@pytest.mark.parametrize("unit, expected", [("millimeter", "mm"), ("angstrom", "A"), ("inch", None), (None, None)])
def test_an_ome_zarr_world_unit_is_its_x_axis_unit_where_it_is_one(tmp_path, capsys, unit, expected):
    """An OME-Zarr image's unit as clwave names it, said by ``clwave info``; None for a unit that is no world unit
    (an inch), none given, or a plain Zarr array (no metadata)."""
    path, _ = _ome(tmp_path, fmt=3)
    attrs = zarr.open_group(path, mode="r+").attrs
    ome = attrs["ome"]
    for axis in ome["multiscales"][0]["axes"][2:]:
        axis.update({} if unit is None else {"unit": unit})
    attrs["ome"] = ome
    zarr.create_array(tmp_path / "plain.zarr", data=np.zeros((2, 3, 4), np.float32))
    assert load(path).unit == expected and load(tmp_path / "plain.zarr").unit is None
    assert main(["info", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["unit"] == expected


def _meta(tmp_path, **change):
    return _ome(tmp_path, **change)[0]


@pytest.mark.parametrize("make, error, words", [
    (lambda p: _meta(p, levels=[{"path": "0", "coordinateTransformations": [{"type": "scale", "scale": [1, 2]}]}]),
     FileFormatError, ["scale", "5 finite numbers"]),
    (lambda p: _meta(p, levels=[{"path": "0", "coordinateTransformations": [
        {"type": "scale", "scale": [1, 1, 0.0, 1, 1]}]}]), FileFormatError, ["must be positive"]),
    (lambda p: _meta(p, levels=[]), FileFormatError, ["datasets"]),
    (lambda p: _meta(p, levels=[{"path": "9"}]), FileFormatError, ["'9'", "does not hold"]),
    (lambda p: _meta(p, axes=("q", "c", "z", "y", "x")), FileFormatError, ["axes", "'q'"]),
    (lambda p: _meta(p, axes=("c", "z", "y", "x")), FileFormatError, ["4 axes", "(1, 2, 4, 5, 6)"]),
    (lambda p: _meta(p, image_scale=[{"type": "affine", "affine": [1]}]), FileFormatError, ["affine"]),
], ids=["scale-length", "non-positive-scale", "no-datasets", "missing-dataset", "unknown-axis", "axes-count",
        "unsupported-transform"])
def test_inconsistent_ngff_metadata_is_named(tmp_path, make, error, words):
    with pytest.raises(error) as excinfo:
        load(make(tmp_path))
    one_line(excinfo, "OME-Zarr", *words)


def test_ome_zarr_time_axis_longer_than_one_is_refused(tmp_path):
    group = zarr.open_group(tmp_path / "t.zarr", mode="w", zarr_format=2)
    group.create_array("0", data=np.zeros((3, 4, 5, 6), np.uint8))
    group.attrs["multiscales"] = [{"axes": [{"name": a} for a in "tzyx"], "datasets": [{"path": "0"}]}]
    with pytest.raises(FileFormatError) as excinfo:
        load(tmp_path / "t.zarr")
    one_line(excinfo, "3 time points")


def test_missing_level_names_the_levels(tmp_path):
    path, _ = _ome(tmp_path)
    with pytest.raises(InputError) as excinfo:
        load(path, level=2)
    one_line(excinfo, "level=2", "0 (1, 2, 4, 5, 6)", "1 (1, 2, 2, 3, 3)")
    assert "--level 2" in excinfo.value.cli_message()


# --------------------------------------------------------------------------- bad stores and options

def test_bad_stores_and_options(tmp_path, volume):
    _hdf5_path(tmp_path, volume)
    with pytest.raises(FileFormatError) as excinfo:
        load(f"{tmp_path / 'v.hdf5'}:/group/nope")
    one_line(excinfo, "/group/nope", "/group/ct (9, 10, 11) int16", "/group/other")
    with pytest.raises(FileFormatError) as excinfo:           # two volumes and no name
        load(tmp_path / "v.hdf5")
    one_line(excinfo, "2 3-D/4-D arrays", ":/NAME")
    with h5py.File(tmp_path / "flat.h5", "w") as fh:
        fh["image"] = np.zeros((4, 5))
    with pytest.raises(FileFormatError) as excinfo:
        load(f"{tmp_path / 'flat.h5'}:/image")
    one_line(excinfo, "(4, 5)", "3-D")

    _zarr_in_group(tmp_path, volume)
    with pytest.raises(FileFormatError) as excinfo:
        load(f"{tmp_path / 'g.zarr'}:/scans/mr")
    one_line(excinfo, "/scans/mr", "/scans/ct", "/mask")
    (tmp_path / "empty.zarr").mkdir()
    with pytest.raises(FileFormatError) as excinfo:
        load(tmp_path / "empty.zarr")
    one_line(excinfo, "not a Zarr store")

    np.save(tmp_path / "v.npy", volume)
    with pytest.raises(InputError) as excinfo:
        load(tmp_path / "v.npy", chunks=0)
    one_line(excinfo, "chunks=0")
    with pytest.raises(InputError) as excinfo:
        load(tmp_path / "v.npy", level=1)
    one_line(excinfo, "level=", "OME-Zarr")
    nib.save(nib.Nifti1Image(volume, np.eye(4)), tmp_path / "v.nii.gz")
    with pytest.raises(InputError) as excinfo:
        load(tmp_path / "v.nii.gz", chunks=4)
    one_line(excinfo, "gunzip")
    assert not load(tmp_path / "v.nii.gz").chunked


def test_too_many_chunks_are_refused_up_front(tmp_path, monkeypatch):
    zarr.create_array(tmp_path / "v.zarr", shape=(50, 50, 50), dtype="uint8", chunks=(50, 50, 50))
    monkeypatch.setattr(shared, "MAX_CHUNKS", 1000)
    with pytest.raises(InputError) as excinfo:
        load(tmp_path / "v.zarr", chunks=4)
    one_line(excinfo, "2,197 chunks", "bigger chunk edge")
    assert load(tmp_path / "v.zarr", chunks=5).data.npartitions == 1000


# --------------------------------------------------------------------------- classification of chunked volumes

def _chunked(data, chunks):
    return Volume(da.from_array(data, chunks=chunks), spacing=(1.0, 2.0, 0.5), origin=(1, 2, 3))


@pytest.mark.parametrize("channels, window", [(1, (-1.0, 2.5)), (1, "auto"), (3, None), (4, "auto")])
def test_chunked_classification_is_bit_identical(rng, monkeypatch, channels, window):
    monkeypatch.setattr(tf_passes, "AUTO_SAMPLES", 500)   # the auto window's strided subsample at work
    shape = (13, 17, 19) + ((channels,) if channels > 1 else ())
    data = rng.normal(size=shape) if channels == 1 else rng.integers(0, 256, shape).astype(np.uint8)
    tf = TransferFunction.preset("hydrogen", window=window)
    whole, chunked = Volume(data, spacing=(1.0, 2.0, 0.5), origin=(1, 2, 3)), _chunked(data, (5, 6, 7) + shape[3:])
    rgba = tf.classify(chunked)
    assert rgba.chunked and rgba.channels == 4 and (rgba.spacing, rgba.origin) == (whole.spacing, whole.origin)
    np.testing.assert_array_equal(rgba.data.compute(), tf.classify(whole).data)
    assert tf.resolved(chunked) == tf.resolved(whole)


def test_strided_subsample_of_chunks_is_the_flat_stride(rng):
    data = rng.normal(size=(11, 12, 13, 3))
    for step in (1, 5, 29, 2000):
        blocks = [tf_passes.sampled(data[a:b, c:d, e:f], (a, c, e), data.shape[:3], step)
                  for a, b in ((0, 4), (4, 11)) for c, d in ((0, 7), (7, 12)) for e, f in ((0, 13),)]
        expected = data.reshape(-1, 3)[::step]
        np.testing.assert_array_equal(tf_passes.sampled(data, (0, 0, 0), data.shape[:3], step), expected)
        np.testing.assert_array_equal(np.sort(np.concatenate(blocks), axis=0), np.sort(expected, axis=0))


# --------------------------------------------------------------------------- phantoms by blocks, make_zarr

@pytest.mark.parametrize("name", NAMES)
def test_phantom_blocks_are_the_phantom(name):
    whole = phantom(name, 21).data
    for box in (np.s_[:, :, :], np.s_[0:5, 3:20, 7:8], np.s_[10:21, 0:4, 5:16]):
        np.testing.assert_array_equal(phantom_block(name, (21, 21, 21), box), whole[box])
    tall = phantom_block(name, (24, 12, 6))       # each axis its own scale: the domain spans the grid
    assert tall.shape == (24, 12, 6)
    np.testing.assert_array_equal(phantom_block(name, (24, 12, 6), np.s_[5:17, 2:, :3]), tall[5:17, 2:, :3])
    with pytest.raises(InputError):
        phantom_block(name, (24, 12, 6), np.s_[0:5:2, :, :])


def _make_zarr():
    spec = importlib.util.spec_from_file_location("make_zarr", Path(__file__).parents[1] / "tools" / "make_zarr.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.main


@pytest.mark.parametrize("name", NAMES)
def test_make_zarr_writes_the_phantom(tmp_path, name, capsys):
    make_zarr = _make_zarr()
    make_zarr([str(tmp_path / "p.zarr"), "--phantom", name, "--shape", "23", "--chunks", "8,10,23",
               "--zarr-format", "2"])
    vol = load(tmp_path / "p.zarr")
    assert zarr.open_array(tmp_path / "p.zarr", mode="r").chunks == (8, 10, 23)
    np.testing.assert_array_equal(vol.data.compute(), phantom(name, 23).data)
    assert "wrote" in capsys.readouterr().out


def test_make_zarr_ome_levels_and_integers(tmp_path):
    make_zarr = _make_zarr()
    make_zarr([str(tmp_path / "o.zarr"), "--shape", "16,12,8", "--chunks", "5", "--ome", "--levels", "2",
               "--spacing", "2,1,0.5", "--origin", "10,20,30", "--unit", "micrometer", "--dtype", "uint16",
               "--scale", "65535"])
    vol = load(tmp_path / "o.zarr")
    assert vol.shape == (16, 12, 8) and vol.spacing == (2.0, 1.0, 0.5) and vol.origin == (10.0, 20.0, 30.0)
    np.testing.assert_array_equal(vol.data.compute(),
                                  np.rint(phantom_block("hydrogen", (16, 12, 8)) * 65535.0).astype(np.float32))
    coarse = load(tmp_path / "o.zarr", level=1)     # the same box, half the voxels per axis
    assert coarse.shape == (8, 6, 4) and coarse.spacing == (4.0, 2.0, 1.0) and coarse.origin == vol.origin


def test_a_dask_array_of_unknown_chunk_sizes_is_refused_at_volume():
    """``d[d[:, 0, 0] > -1]`` has chunks (nan, ...): Volume() took it and its shape, or the transform, failed with
    "cannot convert float NaN to integer"; refused at once, naming compute_chunk_sizes(), which makes it usable."""
    d = da.from_array(np.arange(4 * 5 * 6, dtype=np.float32).reshape(4, 5, 6), chunks=2)
    unknown = d[d[:, 0, 0] > -1]
    with pytest.raises(InputError, match=r"^this Dask array's shape \(nan, 5, 6\) is unknown .*; give "
                                         r"dask_array\.compute_chunk_sizes\(\) first$"):
        Volume(unknown)
    assert Volume(unknown.compute_chunk_sizes()).shape == (4, 5, 6)
