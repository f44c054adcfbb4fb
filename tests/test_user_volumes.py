"""Volumes as users hand them: NaN voxels as "no data" (FSL and SPM write NaN outside their masks), which
``load(path, nan=VALUE)`` and ``--nan VALUE`` give a value in the file's units before anything else
(docs/coordinates.md §1), else refused in one line naming the option; a time series told as one."""

import re

import nibabel as nib
import numpy as np
import pytest

import clwave
from clwave.cli import main
from clwave.errors import InputError


@pytest.fixture
def masked(tmp_path):
    """A float64 ball of values 50..100 with NaN outside it, as a .npy and a NIfTI (a statistical map's layout)."""
    z, y, x = np.mgrid[:12, :12, :12] - 5.5
    r = np.sqrt(x * x + y * y + z * z)
    data = np.where(r < 5, 100.0 - 10 * r, np.nan)
    np.save(tmp_path / "m.npy", data)
    nib.save(nib.Nifti1Image(data.transpose(2, 1, 0).copy(), np.eye(4)), tmp_path / "m.nii")
    return tmp_path, data


def test_nan_voxels_take_the_value_given_before_the_subtraction(masked):
    folder, data = masked
    with pytest.raises(InputError, match=r"non-finite voxel.*load\(path, nan=0.0\)"):
        clwave.load(folder / "m.npy")
    vol = clwave.load(folder / "m.npy", nan=-5.0, subtract=-5.0)  # NaN -> -5 in the file's units, then +5
    expected = np.where(np.isnan(data), -5.0, data) + 5.0
    np.testing.assert_array_equal(vol.data, expected.astype(np.float32))
    assert vol.subtracted == -5.0 and np.count_nonzero(vol.data == 0) == np.count_nonzero(np.isnan(data))
    chunked = clwave.load(folder / "m.npy", nan=-5.0, subtract=-5.0, chunks=5)  # the same, chunk by chunk
    np.testing.assert_array_equal(np.asarray(chunked.data), vol.data)
    nifti = clwave.load(folder / "m.nii", nan=0.0)  # RAS: the ball is symmetric, x flipped or not
    assert np.isfinite(nifti.data).all() and np.count_nonzero(nifti.data) == np.count_nonzero(~np.isnan(data))
    with pytest.raises(InputError, match="nan=inf must be finite"):
        clwave.load(folder / "m.npy", nan=float("inf"))


def test_nan_on_the_command_line(masked, capsys, monkeypatch):
    folder, _ = masked
    monkeypatch.chdir(folder)
    assert main(["compress", "m.nii", "-o", "a.clw"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "give NaN voxels a value with --nan VALUE (no data, e.g. 0)" in err
    assert main(["compress", "m.nii", "--nan", "0", "--levels", "1", "-o", "a.clw"]) == 0
    assert clwave.WaveletVolume.open("a.clw").channels == 1
    for argv, needle in ((["m.nii", "--nan", "nan"], "--nan"), (["phantom:hydrogen:16", "--nan", "0"],
                                                                "--nan cannot apply to phantom:hydrogen:16")):
        capsys.readouterr()
        assert main(["compress", *argv, "-o", "b.clw"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and needle in err, err


def test_a_time_series_is_told_as_one(tmp_path, capsys, monkeypatch):
    """A (t, z, y, x) array read as (z, y, x, c) of 16 channels: the refusal names a time series and the way (trial21:
    it spoke of channels only)."""
    with pytest.raises(InputError, match=r"a time series \(t, z, y, x\) is rendered one time point at a time: give "
                                         r"one, e.g. data\[t\]"):
        clwave.Volume(np.zeros((5, 16, 16, 16), np.float32))
    np.save(tmp_path / "ts.npy", np.zeros((5, 16, 16, 16), np.float32))
    monkeypatch.chdir(tmp_path)
    assert main(["compress", "ts.npy", "-o", "ts.clw"]) == 2
    assert "one time point at a time: write one to a file (or dataset) of its own" in capsys.readouterr().err


@pytest.mark.parametrize("shape, drop, index", [((1, 6, 8, 8), 0, "data[0]"), ((6, 1, 8, 8), 1, "data[:, 0]"),
                                                ((6, 8, 1, 8), 2, "data[:, :, 0]")])
def test_a_length_1_axis_of_a_4d_array_is_named_not_squeezed(tmp_path, capsys, monkeypatch, shape, drop, index):
    """trial26 finding 9: a radio cube as astropy gives it, (1, 96, 128, 128) with its degenerate Stokes axis first,
    was refused as "128 channels" with a time series' hint.  A 4-D array whose last axis is no channel count and that
    has a length-1 axis elsewhere names that axis and how to drop it (never squeezed silently: which axis is z is the
    user's to say); the command line names numpy.squeeze on the array written."""
    with pytest.raises(InputError, match=rf"shape {re.escape(str(shape))} has a length-1 axis {drop} .*drop it: "
                                         rf"{re.escape(index)} \(numpy.squeeze\(data, axis={drop}\)\)") as e:
        clwave.Volume(np.zeros(shape, np.float32))
    assert "\n" not in str(e.value) and "time series" not in str(e.value)
    np.save(tmp_path / "s.npy", np.zeros(shape, ">f4"))
    monkeypatch.chdir(tmp_path)
    for command in (["info", "s.npy"], ["compress", "s.npy", "-o", "s.clw"]):
        assert main(command) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"length-1 axis {drop}" in err and "numpy.squeeze(data, axis=" in err, err
    assert not (tmp_path / "s.clw").exists()
