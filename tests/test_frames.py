"""One time point of a time series (``load(frame=K)``, ``--frame K``): a 4-D NIfTI, an MGH file of frames, an ImageJ
hyperstack and an OME-TIFF with an axis T, an OME-Zarr image with an axis t, a FITS cube with Stokes planes.  The
oracle of each: the same volume written here as a 3-D file of the same format, which loads equal, bit for bit, with
equal spacing and origin; and each read of the series reads that time point alone (its chunks, pages, planes or
bytes), whole or chunk by chunk."""

import json

import nibabel
import numpy as np
import pytest
import tifffile
import zarr
from astropy.io import fits

import clwave
from clwave.errors import FileFormatError, InputError
from clwave.io.loaders import describe
from test_cli_info import run

T = 3  # time points of every series here
SKY = dict(CTYPE1="RA---SIN", CTYPE2="DEC--SIN", CTYPE3="VRAD", CDELT1=-0.001, CDELT2=0.002, CDELT3=5000.0,
           CRVAL1=150.0, CRVAL2=2.0, CRPIX1=4.0, CRPIX2=3.0)


# The writers: ``data`` a series (4-D, time last) or its volume at time point ``t`` (3-D)
def _nifti(path, data, t=None):
    """Integers scaled by scl_slope and scl_inter (read as float32 a slab at a time, nifti._ScaledToFloat32)."""
    affine = np.array([[0.0, 0, -2.5, 10], [1.5, 0, 0, -4], [0, 3.0, 0, 7], [0, 0, 0, 1]])  # axes turned, one flipped
    image = nibabel.Nifti1Image(data, affine)
    image.header.set_slope_inter(0.25, -7.0)
    nibabel.save(image, path)


def _mgh(path, data, t=None):
    affine = np.array([[-1.0, 0, 0, 3], [0, 0, 2.0, -1], [0, -1.5, 0, 4], [0, 0, 0, 1]])
    nibabel.save(nibabel.MGHImage(data, affine), path)


def _imagej(path, data, t=None):
    tifffile.imwrite(path, np.moveaxis(data, -1, 0) if data.ndim == 4 else data, imagej=True, resolution=(2.0, 4.0),
                     metadata={"axes": "TZYX" if data.ndim == 4 else "ZYX", "spacing": 3.0, "unit": "um",
                               "finterval": 1.5})


def _ome_tiff(path, data, t=None):
    """An OME-TIFF whose planes' positions move with time (x by 10 a time point): a time point is placed where its own
    planes are, as the 3-D file of it is where its planes are."""
    series = data.ndim == 4
    points = range(T) if series else [t]
    positions = {"PositionX": [10.0 * p for p in points for _ in range(data.shape[0])],
                 "PositionY": [1.0] * (len(points) * data.shape[0]),
                 "PositionZ": [0.5 * z for _ in points for z in range(data.shape[0])]}
    tifffile.imwrite(path, np.moveaxis(data, -1, 0) if series else data, ome=True,
                     metadata={"axes": "TZYX" if series else "ZYX", "PhysicalSizeX": 0.5, "PhysicalSizeY": 0.25,
                               "PhysicalSizeZ": 2.0, "Plane": positions})


def _ome_zarr(path, data, t=None):
    series = data.ndim == 4
    group = zarr.open_group(path, mode="w", zarr_format=2)
    stored = np.moveaxis(data, -1, 0) if series else data  # (t, z, y, x)
    group.create_array("0", data=stored, chunks=(1, 2, 3, 3) if series else (2, 3, 3))
    axes = ([{"name": "t", "type": "time", "unit": "second"}] if series else []) + \
        [{"name": a, "type": "space", "unit": "micrometer"} for a in "zyx"]
    scale, shift = [2.0, 0.5, 0.25], [1.0, -2.0, 3.0]
    placed = [{"type": "scale", "scale": [0.5] * series + scale},
              {"type": "translation", "translation": [0.0] * series + shift}]
    levels = [{"path": "0", "coordinateTransformations": placed}]
    group.attrs["multiscales"] = [{"version": "0.4", "axes": axes, "datasets": levels}]


def _fits(path, data, t=None):
    """Stokes I, Q, U, V (here T of them) on a 4th axis beside a (VRAD, Dec, RA) cube; the 3-D file: one plane."""
    cards = dict(SKY, **(dict(CTYPE4="STOKES", CDELT4=1.0, CRVAL4=1.0, CRPIX4=1.0) if data.ndim == 4 else {}))
    stored = np.moveaxis(data, -1, 0) if data.ndim == 4 else data  # numpy order: (STOKES, VRAD, Dec, RA)
    fits.PrimaryHDU(stored, fits.Header(cards)).writeto(path)


#: name, writer, sample type, and the chunks= each is read with (besides whole)
FORMATS = {"s.nii": (_nifti, np.int16), "s.nii.gz": (_nifti, np.int16), "s.mgh": (_mgh, np.float32),
           "s.mgz": (_mgh, np.int32), "s.tif": (_imagej, np.uint16), "s.ome.tif": (_ome_tiff, np.uint8),
           "s.zarr": (_ome_zarr, np.int16), "s.fits": (_fits, np.float32)}
CHUNKED = ("s.nii", "s.mgh", "s.tif", "s.ome.tif", "s.zarr", "s.fits")  # gzip cannot seek: .nii.gz, .mgz read whole


def _series(tmp_path, name, rng):
    """The series ``name`` written, and its volumes: (x, y, z, t) for NIfTI and MGH, else (z, y, x, t)."""
    write, dtype = FORMATS[name]
    data = rng.integers(0, 200, (4, 5, 6, T)).astype(dtype)
    write(tmp_path / name, data)
    return data


@pytest.mark.parametrize("name", list(FORMATS))
def test_a_frame_loads_as_the_3d_file_of_that_volume(tmp_path, rng, name):
    write, _ = FORMATS[name]
    data = _series(tmp_path, name, rng)
    for k in (0, 2, -2):
        one = tmp_path / f"one{k}_{name}"
        write(one, np.ascontiguousarray(data[..., k]), k % T)
        expected = clwave.load(one)
        for chunks in (None, False) + ((2,) if name in CHUNKED else ()):
            got = clwave.load(tmp_path / name, frame=k, chunks=chunks)
            assert got.chunked == (chunks == 2) or name == "s.zarr", (name, chunks)
            assert got.data.dtype == np.float32 and np.array_equal(np.asarray(got.data), np.asarray(expected.data)), \
                (name, k)
            assert (got.spacing, got.origin, got.unit, got.obliquity) == \
                (expected.spacing, expected.origin, expected.unit, expected.obliquity), (name, k, chunks)


@pytest.mark.parametrize("name", ["s.nii", "s.mgh", "s.tif", "s.ome.tif", "s.zarr", "s.fits"])
def test_a_frame_reads_its_own_samples_alone(tmp_path, rng, monkeypatch, name):
    """The reads under each loader are recorded: every one is of the picked time point (a NIfTI's or MGH's proxy of
    one volume's bytes, a TIFF region or a FITS section whose time index is k, a Zarr store's chunks of time k)."""
    _series(tmp_path, name, rng)
    seen = []
    if name in ("s.nii", "s.mgh"):
        from nibabel.arrayproxy import ArrayProxy

        unscaled = ArrayProxy._get_unscaled
        monkeypatch.setattr(ArrayProxy, "_get_unscaled", lambda self, slicer: seen.append(
            (self.shape, self.offset)) or unscaled(self, slicer))
        size = 4 * 5 * 6 * np.dtype(FORMATS[name][1]).itemsize
        from nibabel.freesurfer.mghformat import DATA_OFFSET

        with open(tmp_path / name, "rb") as fh:
            first = DATA_OFFSET if name == "s.mgh" else nibabel.Nifti1Header.from_fileobj(fh).get_data_offset()
        expected = [((4, 5, 6), first + 2 * size)]
    elif name in ("s.tif", "s.ome.tif"):
        from clwave.io.loaders import tiff

        region = tiff._read_region
        monkeypatch.setattr(tiff, "_read_region", lambda path, pages, index: seen.append(index[0]) or region(
            path, pages, index))
        monkeypatch.setattr(tifffile.TiffPageSeries, "asarray", lambda *a, **k: pytest.fail("the whole series read"))
        expected = [2]
    elif name == "s.zarr":
        import zarr.core.array

        getitem = zarr.Array.__getitem__
        monkeypatch.setattr(zarr.Array, "__getitem__", lambda self, index: seen.append(index[0]) or getitem(
            self, index))
        expected = [2]
    else:
        section = fits.hdu.image.Section.__getitem__
        monkeypatch.setattr(fits.hdu.image.Section, "__getitem__", lambda self, key: seen.append(key[0]) or section(
            self, key))
        expected = [slice(2, 3), 2]  # astropy's section reads a plane at a time
    clwave.load(tmp_path / name, frame=2, chunks=False)
    assert seen and all(s in expected for s in seen), (name, seen)
    seen.clear()
    np.asarray(clwave.load(tmp_path / name, frame=-1, chunks=2).data)
    assert seen and all(s in expected for s in seen), (name, seen)


def test_a_series_read_without_frame_names_the_option_and_the_range(tmp_path, rng):
    for name in FORMATS:
        _series(tmp_path, name, rng)
        with pytest.raises(FileFormatError) as refused:
            clwave.load(tmp_path / name)
        words = {"s.fits": "3 planes along its axis 4 (STOKES)", "s.mgh": "3 frames", "s.mgz": "3 frames"}.get(
            name, "3 time points")
        assert words in str(refused.value) and "\n" not in str(refused.value), name
        assert str(refused.value).endswith("; clwave reads one volume: pick one, frame=K for K in 0 .. 2 (or -3 .. "
                                           "-1 from the end)"), name
        assert refused.value.cli_message().endswith("pick one, --frame K for K in 0 .. 2 (or -3 .. -1 from the end)")


def test_frame_out_of_range_or_of_one_volume_or_not_a_number_is_one_line(tmp_path, rng):
    _series(tmp_path, "s.nii", rng)
    for frame in (3, -4, 10 ** 12):
        with pytest.raises(InputError) as refused:
            clwave.load(tmp_path / "s.nii", frame=frame)
        assert str(refused.value) == f"frame={frame} is out of range: {tmp_path / 's.nii'} holds 3 time points, 0 .. " \
                                     f"2 (or -3 .. -1 from the end)"
        assert refused.value.cli_message().startswith(f"--frame {frame} is out of range: ")
    with pytest.raises(InputError, match="out of range: .* holds 3 planes along STOKES, 0 .. 2"):
        _series(tmp_path, "s.fits", rng)
        clwave.load(tmp_path / "s.fits", frame=3)
    for frame in (True, 1.0, "1", np.float32(1)):
        with pytest.raises(InputError, match="must be a whole number, the 0-based index of a time point"):
            clwave.load(tmp_path / "s.nii", frame=frame)
    assert clwave.load(tmp_path / "s.nii", frame=np.int64(1)).shape == clwave.load(tmp_path / "s.nii", frame=1).shape
    # one volume: in a format that has time series, or in one that has none
    nibabel.save(nibabel.Nifti1Image(np.zeros((4, 5, 6, 1), np.int16), np.eye(4)), tmp_path / "one.nii")
    zarr.open_group(tmp_path / "plain.zarr", mode="w", zarr_format=2).create_array("v", data=np.zeros((4, 5, 6)))
    np.save(tmp_path / "v.npy", np.zeros((4, 5, 6), np.float32))
    for path in (tmp_path / "one.nii", tmp_path / "plain.zarr:/v"):
        with pytest.raises(InputError) as refused:
            clwave.load(path, frame=0)
        assert str(refused.value).startswith("frame=0 picks one volume of a time series; ") and \
            str(refused.value).endswith(" holds one volume (no time axis of several points): leave it out")
    with pytest.raises(InputError, match=r"^frame= only applies to time series \(NIfTI, MGH, TIFF, OME-Zarr and FITS "
                                         r"files\); leave it out for a npy input$"):
        clwave.load(tmp_path / "v.npy", frame=0)


def test_a_vector_time_series_is_refused_with_frame_in_one_line(tmp_path):
    """A 5-D NIfTI of time points and vector components: its time points are not contiguous, and not picked."""
    nibabel.save(nibabel.Nifti1Image(np.zeros((4, 5, 6, 3, 2), np.float32), np.eye(4)), tmp_path / "v.nii")
    with pytest.raises(FileFormatError, match="a time series of 2 components a voxel, whose time points clwave does "
                                              "not pick"):
        clwave.load(tmp_path / "v.nii", frame=1)


def test_the_commands_read_the_frame_and_refuse_it_in_one_line(tmp_path, rng, capsys):
    data = _series(tmp_path, "s.nii", rng)
    _nifti(tmp_path / "one.nii", np.ascontiguousarray(data[..., -1]))
    for name, frame in (("s.nii", ["--frame", "-1"]), ("one.nii", [])):
        code, out, err = run(capsys, "compress", str(tmp_path / name), *frame, "--levels", "1", "--keep", "0.5", "-o",
                             str(tmp_path / f"{name}.clw"))
        assert code == 0, err
    a, b = (clwave.WaveletVolume.open(tmp_path / f"{name}.clw") for name in ("s.nii", "one.nii"))
    assert (a.spacing, a.origin) == (b.spacing, b.origin)
    np.testing.assert_array_equal(a.reconstruct().data, b.reconstruct().data)
    code, out, err = run(capsys, "render", str(tmp_path / "s.nii"), "--size", "8", "-o", str(tmp_path / "r.png"))
    assert code == 2 and err.strip().endswith("pick one, --frame K for K in 0 .. 2 (or -3 .. -1 from the end)") \
        and len(err.strip().splitlines()) == 1, err
    (tmp_path / "poses.csv").write_text("azimuth,elevation\n0,0\n")
    drr = ["--poses", str(tmp_path / "poses.csv"), "-o", str(tmp_path / "d.npy")]
    for argv, words in ((["s.nii", "--frame", "3"], "--frame 3 is out of range: "),
                        (["one.nii", "--frame", "0"], "--frame 0 picks one volume of a time series")):
        path = str(tmp_path / argv[0])
        for command in (["drr", path, *argv[1:], *drr], ["info", path, *argv[1:]]):
            code, out, err = run(capsys, *command)
            assert code == 2 and words in err and len(err.strip().splitlines()) == 1, (command, err)
    code, out, err = run(capsys, "drr", "phantom:hydrogen:8", "--frame", "0", *drr)
    assert code == 2 and "--frame cannot apply to phantom:hydrogen:8" in err, err
    code, out, err = run(capsys, "compress", str(tmp_path / "one.clw"), "--frame", "0", "-o", str(tmp_path / "x.clw"))
    assert code == 2 and "--frame cannot apply to " in err, err


def test_info_lists_the_frames_and_describes_the_one_picked(tmp_path, rng, capsys):
    _series(tmp_path, "s.nii", rng)
    _series(tmp_path, "s.fits", rng)
    code, out, err = run(capsys, "info", str(tmp_path / "s.nii"))
    lines = dict(line.split(None, 1) for line in out.splitlines())
    assert code == 0 and "volume" not in lines and lines["time"] == "3 time points, 1 (no unit) apart: --frame K " \
        "picks one, 0 .. 2 (or -3 .. -1 from the end); without it compress, render, progressive, drr and view refuse " \
        "the file", out  # nibabel's pixdim[4], 1 in no unit
    code, out, err = run(capsys, "info", str(tmp_path / "s.nii"), "--frame", "-1", "--json")
    facts = json.loads(out)
    one = clwave.load(tmp_path / "s.nii", frame=-1)
    assert code == 0 and facts["time"] == dict(points=3, step=1.0, unit=None, along="time", frame=2), err
    assert facts["refused"] is None and facts["shape"] == list(one.shape) and \
        (tuple(facts["spacing"]), tuple(facts["origin"])) == (one.spacing, one.origin)
    code, out, err = run(capsys, "info", str(tmp_path / "s.nii"), "--frame", "1")
    lines = dict(line.split(None, 1) for line in out.splitlines())
    assert lines["time"] == "3 time points, 1 (no unit) apart: --frame 1 read" and lines["volume"].startswith(
        f"{one.shape[2]} x {one.shape[1]} x {one.shape[0]} voxels"), out
    code, out, err = run(capsys, "info", str(tmp_path / "s.fits"))
    lines = dict(line.split(None, 1) for line in out.splitlines())
    assert code == 0 and lines["time"].startswith("3 planes along STOKES, 1 (no unit) apart: --frame K picks one"), out
    assert "4 STOKES (3, 1 a pixel) one plane (--frame)" in lines["axes"], out
    assert describe(tmp_path / "s.fits", frame=0)["time"]["frame"] == 0


@pytest.mark.parametrize("name", list(FORMATS))
def test_describe_places_the_frame_as_load_reads_it(tmp_path, rng, name):
    """describe(frame=K), clwave info FILE --frame K: that volume's shape, spacing and origin as load gives them (an
    OME-TIFF's time point 2 where its own planes are, 20 um from time point 0's), the time points with K."""
    _series(tmp_path, name, rng)
    for k in (2, -3):
        facts, one = describe(tmp_path / name, frame=k), clwave.load(tmp_path / name, frame=k)
        assert facts["time"]["points"] == 3 and facts["time"]["frame"] == k % 3 and facts["refused"] is None, name
        assert (facts["shape"], tuple(facts["spacing"]), tuple(facts["origin"])) == \
            (list(one.shape), one.spacing, one.origin), (name, k)


def test_a_viewers_frame_goes_into_its_python(tmp_path):
    """`clwave view FILE --frame K`'s Python snippet reads that frame (clwave.load(..., frame=K))."""
    import argparse

    from clwave.view.export import Origin, _model, Spec

    args = argparse.Namespace(input=str(tmp_path / "s.nii"), frame=-1)
    origin = Origin.of_args(args)
    assert ("frame", "--frame", -1) in origin.options
    lines = _model(origin, Spec("xray", clwave.Camera(), levels=1))
    assert f"vol = clwave.load({str(tmp_path / 's.nii')!r}, frame=-1)" in lines
