"""The header of a ``.clw`` file read alone (clwave/io/clw.py ``read_header``): what ``read_clw`` reads of it on a
good file, and on a bad one the same one-line error ``read_clw`` gives."""

import numpy as np
import pytest

from clwave.errors import FileFormatError
from clwave.io.clw import read_clw, read_header
from clwave.io.summary import approximation_occupancy
from test_hardening import crafted, setter


def test_the_header_alone_is_what_the_whole_file_says(model_file, monkeypatch):
    from clwave.io import clw

    monkeypatch.setattr(clw, "_read_group", None)  # no coefficient is read
    header = read_header(model_file)
    monkeypatch.undo()
    wv = read_clw(model_file)
    assert tuple(header["shape"]) == wv.shape and header["levels"] == wv.levels
    assert header["channels"] == wv.channels and [g["channels"] for g in header["groups"]] == [
        list(g.channels) for g in wv.groups]
    assert np.allclose(header["spacing"], wv.spacing) and np.allclose(header["origin"], wv.origin)


def flip(h5):
    h5.attrs["header"] = h5.attrs["header"].replace('"levels": 1', '"levels": 0')


def other_hdf5(h5):
    del h5.attrs["format"]


@pytest.mark.parametrize("edit, change", [
    (setter("shape", [-16, 16, 16]), None), (setter("groups", []), None), (setter("channels", 3), None),
    (setter("spacing", [0, 1, 1]), None), (setter("levels", 9), None), (setter("version", 99), None),
    (setter("focus", [[1, 2, 3]]), None), (setter("transfer_function", [1, 2]), None),
    (setter("value_range", [255, 0]), None), (setter("value_range", [0, "255"]), None), (None, flip),
    (None, other_hdf5)])
def test_a_bad_header_is_the_error_read_clw_gives(model_file, tmp_path, edit, change):
    path = crafted(model_file, tmp_path, edit, change)
    with pytest.raises(FileFormatError) as whole:
        read_clw(path)
    with pytest.raises(FileFormatError) as alone:
        read_header(path)
    assert str(alone.value) == str(whole.value) and "\n" not in str(alone.value)


def test_files_that_are_no_clw_are_the_error_read_clw_gives(tmp_path):
    npy, old, missing = tmp_path / "x.clw", tmp_path / "old.clw", tmp_path / "missing.clw"
    np.save(tmp_path / "x.npy", np.zeros(8))
    (tmp_path / "x.npy").rename(npy)
    with open(old, "wb") as fh:  # version 1 was a zip of .npy members
        np.savez_compressed(fh, header=np.frombuffer(b'{"version": 1}', np.uint8))
    for path in (npy, old, missing):
        with pytest.raises(FileFormatError) as whole:
            read_clw(path)
        with pytest.raises(FileFormatError) as alone:
            read_header(path)
        assert str(alone.value) == str(whole.value) and "\n" not in str(alone.value)


def occupancy_as(data):
    def change(h5):
        del h5["g0/occupancy"]
        if data is not None:
            h5["g0/occupancy"] = data
        else:
            h5.create_group("g0/occupancy")
    return change


@pytest.mark.parametrize("change, needle", [
    (occupancy_as(np.zeros((3, 3, 3), np.uint8)), "expected"),       # another shape
    (occupancy_as(np.zeros((13, 13, 2), np.float32)), "expected"),   # the band's shape (packed), another type
    (occupancy_as(None), "not a dataset")])
def test_a_forged_occupancy_is_refused_in_one_line(model_file, tmp_path, change, needle):
    """The file's summary of the content mask (docs/chunked.md §4) checked against the header as every dataset: the
    coarse stage that reads it (RayTracer.open) refuses the file in one line naming the member."""
    from clwave.raytrace.tracer import RayTracer

    assert approximation_occupancy(model_file)[0].shape == (13, 13, 13)  # hydrogen 16^3, cubic, one level
    path = crafted(model_file, tmp_path, change=change)
    for read in (approximation_occupancy, RayTracer.open):
        with pytest.raises(FileFormatError, match=needle) as err:
            read(path)
        assert "\n" not in str(err.value) and "occupancy" in str(err.value)
