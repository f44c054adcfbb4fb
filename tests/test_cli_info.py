"""`clwave info FILE`: a .clw's header and a volume file's, without reading a coefficient or a voxel; and the words of
what the commands report (kept coefficients, levels, warnings)."""

import json
from pathlib import Path

import h5py
import numpy as np
import pytest

import clwave
from clwave.cli import main
from test_hardening import crafted, setter


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def unread(monkeypatch):
    """Every HDF5 dataset read is recorded: a header's description reads none of the coefficients."""
    read, getitem = [], h5py.Dataset.__getitem__

    def recorded(self, index):
        read.append(self.name)
        return getitem(self, index)
    monkeypatch.setattr(h5py.Dataset, "__getitem__", recorded)
    return read


@pytest.mark.parametrize("quantise", [None, 1e-3])
def test_info_of_a_clw_is_its_header_and_kept_coefficients(tmp_path, capsys, unread, quantise):
    """Two channel groups (colour cubic, opacity linear), 2 levels, 30 % kept, a transfer function: the JSON gives the
    model's own shape, spacing, origin, levels, channels and each group's kept coefficients (as the model opened from
    the file counts them) and quantisation; the text the same in lines; no coefficient is read."""
    vol = clwave.Volume(np.random.default_rng(1).random((12, 14, 16, 4), np.float32), spacing=(2.0, 1.0, 0.5),
                        origin=(1.0, -2.0, 3.0))
    wv = clwave.WaveletVolume.from_volume(vol, wavelet=["cubic", "cubic", "cubic", "linear"], levels=2)
    wv = wv.threshold(keep=0.3)
    path = tmp_path / "m.clw"
    wv.save(path, quantise=quantise)
    code, out, err = run(capsys, "info", str(path), "--json")
    assert code == 0 and err == "" and not unread, (err, unread)
    facts = json.loads(out)
    stored = clwave.WaveletVolume.open(path)
    assert (facts["shape"], facts["spacing"], facts["origin"], facts["levels"], facts["channels"]) == \
        ([12, 14, 16], [2.0, 1.0, 0.5], [1.0, -2.0, 3.0], 2, 4)
    assert facts["bytes"] == path.stat().st_size
    assert [(g["wavelet"], g["order"], g["channels"]) for g in facts["groups"]] == [("cubic", 4, [0, 1, 2]),
                                                                                    ("linear", 2, [3])]
    assert [g["kept"] for g in facts["groups"]] == [g.kept for g in stored.groups]
    assert [g["share"] for g in facts["groups"]] == [g.kept / (12 * 14 * 16) for g in stored.groups]
    assert all((g["quantisation"] is None) == (quantise is None) for g in facts["groups"])
    if quantise is not None:
        assert all(0 < g["quantisation"] <= quantise for g in facts["groups"])
    code, out, _ = run(capsys, "info", str(path))
    lines = dict(line.split(None, 1) for line in out.splitlines() if not line.startswith("group"))
    assert code == 0 and lines["volume"] == "16 x 14 x 12 voxels (x, y, z), spacing 0.5, 1, 2 (x, y, z), centre 1, " \
                                            "-2, 3, corner voxel (least x, y, z) -2.75, -8.5, -8"
    assert lines["model"] == "2 levels, 4 channels in 2 groups"
    kept = stored.groups[1].kept
    assert f"group 1    channel 3: linear wavelet (order 2), keeps {kept:,} coefficients " \
           f"({100 * kept / (12 * 14 * 16):.2f} % of the voxels)" in out


def test_info_of_a_classified_clw_names_its_transfer_function(tmp_path, capsys):
    path = tmp_path / "c.clw"
    assert main(["compress", "phantom:hydrogen:16", "--tf", "hydrogen", "--levels", "1", "-o", str(path)]) == 0
    capsys.readouterr()
    code, out, _ = run(capsys, "info", str(path))
    assert code == 0 and "transfer   hydrogen, window 0 .. 1, 5 points (classified before the transform)" in out
    assert "model      1 level, 4 channels in 1 group" in out  # one level, not "1 levels"


def test_info_names_a_windowless_transfer_function_and_the_value_subtracted(tmp_path, capsys):
    """A transfer function without a window (its points are values, model.md §5) is no "window auto"; the value
    subtracted (--subtract) is a line of words where it is not 0, and a JSON key always (0 where none is recorded)."""
    tf = clwave.TransferFunction([[-100, 0, 0, 0, 0], [40, 1, 1, 1, 0.5], [500, 1, 1, 1, 1]], name="mine")
    vol = clwave.Volume(np.random.default_rng(2).random((8, 8, 8), np.float32) * 600 - 100)
    plain, moved = tmp_path / "plain.clw", tmp_path / "moved.clw"
    clwave.WaveletVolume.from_volume(vol, levels=1, transfer_function=tf).save(plain)
    clwave.WaveletVolume.from_volume(clwave.Volume(vol.data + 1024, subtracted=-1024.0), levels=1).save(moved)
    code, out, _ = run(capsys, "info", str(plain))
    assert code == 0 and "transfer   mine, window none (points are values, -100 .. 500), 3 points (classified while " \
                         "rendering)" in out and "subtracted" not in out, out
    code, out, _ = run(capsys, "info", str(moved))
    assert code == 0 and "subtracted -1024 from the input's values (--subtract; transfer functions in the " \
                         "input's units)" in out, out
    for path, subtracted in ((plain, 0.0), (moved, -1024.0)):
        code, out, _ = run(capsys, "info", str(path), "--json")
        assert code == 0 and json.loads(out)["subtracted"] == subtracted
    older = crafted(plain, tmp_path, lambda header: header.pop("offset"))  # a file of before the fifteenth session
    code, out, _ = run(capsys, "info", str(older), "--json")
    assert code == 0 and json.loads(out)["subtracted"] == 0.0


def test_info_gives_a_stored_functions_opacity_unit_and_the_inputs_value_range(tmp_path, capsys):
    """A scalar model's stored transfer function: its opacity unit (2 mm; one voxel, the smallest spacing, where None;
    1 world unit for a version-1 function, as a read takes it) in the text and the JSON, and the input's value range
    (its min and max, NumPy's) in both; a file of before the range was recorded says so, null in the JSON."""
    data = np.random.default_rng(3).random((6, 8, 10), np.float32) * 600 - 100
    vol = clwave.Volume(data, spacing=(0.5, 0.25, 0.4), unit="mm")
    tf = clwave.TransferFunction([[-100, 0, 0, 0, 0], [500, 1, 1, 1, 1]], name="mine", opacity_unit=2)
    files = {unit: tmp_path / f"{unit}.clw" for unit in (2.0, None)}
    for unit, path in files.items():
        clwave.WaveletVolume.from_volume(vol, levels=1, transfer_function=tf.under(opacity_unit=unit)).save(path)
    code, out, _ = run(capsys, "info", str(files[2.0]))
    assert code == 0 and "(classified while rendering), opacities per 2 mm\n" in out, out
    assert f"values     {data.min():g} .. {data.max():g}, the input's range (a transfer function classifies the " \
           f"field clamped to it)" in out, out
    code, out, _ = run(capsys, "info", str(files[None]))
    assert code == 0 and "opacities per voxel (the smallest spacing, 0.25 mm)\n" in out, out
    for length, words in ((1.0, "1 world unit"), (3.0, "3 world units")):  # no length unit recorded
        path = tmp_path / f"plain{length:g}.clw"
        plain = clwave.Volume(data, spacing=(0.5, 0.25, 0.4))
        clwave.WaveletVolume.from_volume(plain, levels=1, transfer_function=tf.under(opacity_unit=length)).save(path)
        code, out, _ = run(capsys, "info", str(path))
        assert code == 0 and f"opacities per {words}\n" in out, out
    for unit, path in files.items():
        code, out, _ = run(capsys, "info", str(path), "--json")
        facts = json.loads(out)
        assert code == 0 and facts["transfer_function"]["opacity_unit"] == unit
        assert facts["value_range"] == [float(data.min()), float(data.max())]

    def older(header):  # version 1 (opacities per world unit) and no value range: before the nineteenth session
        header["transfer_function"].update(version=1)
        header["transfer_function"].pop("opacity_unit")
        header.pop("value_range")
    old = crafted(files[None], tmp_path, older)
    code, out, _ = run(capsys, "info", str(old))
    assert code == 0 and "opacities per 1 mm\n" in out and "values     the input's range not recorded" in out, out
    code, out, _ = run(capsys, "info", str(old), "--json")
    facts = json.loads(out)
    assert code == 0 and facts["transfer_function"]["opacity_unit"] == 1.0 and facts["value_range"] is None
    assert clwave.TransferFunction.from_dict(facts["transfer_function"]).opacity_unit == \
        clwave.TransferFunction.from_dict(clwave.WaveletVolume.open(old).transfer_function).opacity_unit


def test_info_of_volume_files_is_what_load_reads_without_a_voxel(tmp_path, capsys, monkeypatch):
    """.npy, .nii and HDF5: the shape, spacing and origin load() gives (its own Volume, read here first), the stored
    dtype; the voxel reads of each format fail here, so none is made.  Formats read whole: the shape as stored."""
    import nibabel
    import tifffile

    data = (np.arange(4 * 5 * 6).reshape(4, 5, 6) % 7).astype(np.int16)
    np.save(tmp_path / "v.npy", data)
    affine = np.diag([2.0, 3.0, 4.0, 1.0])
    for name in ("v.nii", "v.nii.gz"):
        nibabel.save(nibabel.Nifti1Image(data, affine), tmp_path / name)
    nii_gz = clwave.load(tmp_path / "v.nii.gz")  # placed from its header too, as load places it
    with h5py.File(tmp_path / "v.h5", "w") as fh:
        fh["inside/v"] = data
    tifffile.imwrite(tmp_path / "v.tif", data, photometric="minisblack")
    loaded = {name: clwave.load(tmp_path / name) for name in ("v.npy", "v.nii", "v.h5")}
    import clwave.io.loaders.raw as raw
    monkeypatch.setattr(raw, "read_memmap", lambda *a: pytest.fail("a voxel of the .npy was read"))
    monkeypatch.setattr(nibabel.arrayproxy.ArrayProxy, "__getitem__", lambda *a: pytest.fail("a NIfTI voxel read"))
    monkeypatch.setattr(h5py.Dataset, "__getitem__", lambda *a: pytest.fail("an HDF5 voxel read"))
    for name, vol in loaded.items():
        code, out, err = run(capsys, "info", str(tmp_path / name), "--json")
        assert code == 0, err
        facts = json.loads(out)
        assert (tuple(facts["shape"]), tuple(facts["spacing"]), tuple(facts["origin"]), facts["dtype"]) == \
            (vol.shape, vol.spacing, vol.origin, "int16"), name
        assert facts["bytes"] == (tmp_path / name).stat().st_size and facts["spacing_in_file"] == (name == "v.nii")
    code, out, _ = run(capsys, "info", str(tmp_path / "v.nii"))
    assert out.splitlines()[1:] == ["volume     4 x 5 x 6 voxels (x, y, z), 1 channel of int16",
                                    "spacing    2, 3, 4 mm (x, y, z; --spacing 4,3,2), centre 3, 6, 10, corner voxel "
                                    "(least x, y, z) 0, 0, 0 (RAS+)",
                                    "box        8, 15, 24 (x, y, z) mm",
                                    "orient     stored RAS, from the sform (nibabel's choice; sform_code 2, "
                                    "qform_code 0)"]
    for name in ("v.nii.gz", "v.tif"):
        code, out, err = run(capsys, "info", str(tmp_path / name), "--json")
        assert code == 0 and json.loads(out)["stored_shape"] == [4, 5, 6] and json.loads(out)["dtype"] == "int16"
        placed = (tuple(json.loads(out)["spacing"]), tuple(json.loads(out)["origin"])) if name == "v.nii.gz" else None
        assert placed == (None if name == "v.tif" else (nii_gz.spacing, nii_gz.origin)), name  # a TIFF: no place
    code, out, _ = run(capsys, "info", str(tmp_path / "v.nii.gz"))
    assert out.splitlines()[1:] == ["stored     4 x 5 x 6 values of int16, in the file's order of axes",
                                    "volume     4 x 5 x 6 voxels (x, y, z), 1 channel of int16",
                                    "spacing    2, 3, 4 mm (x, y, z; --spacing 4,3,2), centre 3, 6, 10, corner voxel "
                                    "(least x, y, z) 0, 0, 0 (RAS+)",
                                    "box        8, 15, 24 (x, y, z) mm",
                                    "orient     stored RAS, from the sform (nibabel's choice; sform_code 2, "
                                    "qform_code 0)"]


def test_info_of_an_ome_or_imagej_tiff_gives_its_spacing_without_a_voxel(tmp_path, capsys, monkeypatch):
    """A microscopist checks the micrometres read (trial21: info said the spacing "comes with the voxels"): an
    OME-TIFF's PhysicalSize and an ImageJ stack's spacing and resolution are its metadata, given as load() gives them,
    with no pixel read (tifffile's reads fail here)."""
    import tifffile

    data = (np.arange(6 * 8 * 10).reshape(6, 8, 10) % 7).astype(np.uint16)
    tifffile.imwrite(tmp_path / "o.ome.tif", data, ome=True,
                     metadata={"axes": "ZYX", "PhysicalSizeX": 0.5, "PhysicalSizeY": 0.25, "PhysicalSizeZ": 5.0})
    tifffile.imwrite(tmp_path / "ij.tif", data, imagej=True, resolution=(2.0, 4.0),
                     metadata={"spacing": 3.0, "unit": "um", "axes": "ZYX"})
    loaded = {name: clwave.load(tmp_path / name) for name in ("o.ome.tif", "ij.tif")}
    monkeypatch.setattr(tifffile.TiffFile, "asarray", lambda *a, **k: pytest.fail("a TIFF pixel was read"))
    monkeypatch.setattr(tifffile.TiffPageSeries, "asarray", lambda *a, **k: pytest.fail("a TIFF pixel was read"))
    for name, vol in loaded.items():
        code, out, err = run(capsys, "info", str(tmp_path / name), "--json")
        facts = json.loads(out)
        assert code == 0 and (tuple(facts["spacing"]), tuple(facts["origin"])) == (vol.spacing, vol.origin), name
    assert loaded["o.ome.tif"].spacing == (5.0, 0.25, 0.5) and loaded["ij.tif"].spacing == (3.0, 0.25, 0.5)
    code, out, _ = run(capsys, "info", str(tmp_path / "o.ome.tif"))
    # the OME-TIFF's first voxel at 0 (it gives no plane positions): its centre at half its extent
    assert out.splitlines()[3:] == ["spacing    0.5, 0.25, 5 um (x, y, z; --spacing 5,0.25,0.5), centre 2.25, 0.875, "
                                    "12.5, corner voxel (least x, y, z) 0, 0, 0",
                                    "box        5, 2, 30 (x, y, z) um"]
    code, out, _ = run(capsys, "info", str(tmp_path / "ij.tif"), "--json")  # its unit, "um" as micron and µm are
    assert json.loads(out)["unit"] == "um" and json.loads(out)["box"] == [5.0, 2.0, 18.0]


def test_a_header_declared_passes_every_handler_of_read_errors(tmp_path):
    """describe's stop before the voxels (shared.Declared) is no error: a loader's ``except Exception`` (reading(),
    which turns a library's error into a FileFormatError) lets it through, its shape and type with it."""
    from clwave.io.loaders.shared import Declared, check_whole, reading

    def declared(voxels, channels):
        raise Declared()
    with pytest.raises(Declared) as stop:
        with reading(tmp_path / "v.dcm"):
            check_whole(tmp_path / "v.dcm", (4, 5, 6), np.int16, declared)
    assert (stop.value.shape, stop.value.dtype, stop.value.resampled) == ((4, 5, 6), np.int16, False)


def test_info_of_a_bad_file_is_one_line(tmp_path, capsys, model_file):
    """A .raw (no header), a missing file, a truncated .clw, a .clw whose header's transfer function is no such
    thing, and device options with a FILE: one line, exit 2."""
    (tmp_path / "v.raw").write_bytes(bytes(64))
    (tmp_path / "cut.clw").write_bytes(model_file.read_bytes()[:3000])
    forged = tmp_path / "forged.clw"
    forged.write_bytes(model_file.read_bytes())
    with h5py.File(forged, "r+") as fh:
        header = json.loads(fh.attrs["header"])
        header["transfer_function"] = {"points": "none"}
        import zlib
        text = json.dumps(header)
        fh.attrs.update(header=text, header_crc32=zlib.crc32(text.encode()))
    for argv, needle in (([str(tmp_path / "v.raw")], "is a .raw file: it has no header"),
                         ([str(tmp_path / "none.clw")], "does not exist"),
                         ([str(tmp_path / "cut.clw")], "the file may be truncated or corrupt"),
                         ([str(forged)], "its transfer function is not valid"),
                         ([str(model_file), "--check"], "--check and --device are about the OpenCL devices"),
                         (["--level", "1"], "give the FILE")):
        code, out, err = run(capsys, "info", *argv)
        assert code == 2 and out == "" and err.startswith("clwave: error:") and err.count("\n") == 1, err
        assert needle in err, err


@pytest.mark.parametrize("key, value, needle", [
    ("focus", [], "focus [] is not [[x, y, z], sigma]"), ("focus", [[1, 2, 3]], "focus [[1, 2, 3]] is not"),
    ("focus", [[0, 0, 0], -1], "a sigma > 0"), ("content", [1], "content [1] is not two corners"),
    ("transfer_function", [1, 2], "its transfer function is not valid"),
    ("interpolate", "yes", "interpolate 'yes' is not true or false")])
def test_a_forged_header_is_the_same_one_line_in_info_and_render(tmp_path, capsys, model_file, key, value, needle):
    """A header value that a render would use is checked where info checks it (io/clw_header.py): each command
    refuses the file in one line naming the value, exit 2."""
    path = crafted(model_file, tmp_path, setter(key, value))
    image = str(tmp_path / "r.png")
    for argv in (["info", str(path)], ["render", str(path), "--size", "8", "-o", image],
                 ["render", str(path), "--method", "raytrace", "--xray", "--size", "8", "-o", image]):
        code, out, err = run(capsys, *argv)
        assert code == 2 and err.startswith(f"clwave: error: cannot read {path}") and err.count("\n") == 1, err
        assert needle in err and not (tmp_path / "r.png").exists(), err


def test_the_commands_words(tmp_path, capsys):
    """drr says how many coefficients it drew, as compress does, and names a refused pose by its number in the
    table; an option for another format is named in the singular."""
    (tmp_path / "poses.csv").write_text("azimuth,elevation\n0,0\n")
    code, out, err = run(capsys, "drr", "phantom:hydrogen:16", "--levels", "1", "--keep", "0.2", "--poses",
                         str(tmp_path / "poses.csv"), "--size", "16", "-o", str(tmp_path / "d.npy"))
    kept = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", 16), levels=1).threshold(keep=0.2).kept
    assert code == 0 and f"(line integrals, splatted) of {kept:,} coefficients ({100 * kept / 16 ** 3:.2f} % of " \
                         f"the voxels)" in out, out + err
    (tmp_path / "bad.csv").write_text("azimuth,elevation,dso\n0,0,100\n10,0,-5\n")
    code, _, err = run(capsys, "drr", "phantom:hydrogen:16", "--poses", str(tmp_path / "bad.csv"), "-o",
                       str(tmp_path / "b.npy"))
    assert code == 2 and err == f"clwave: error: pose table {tmp_path / 'bad.csv'}, pose 2: dso=-5.0 must be a " \
                                f"positive source-to-isocentre distance\n"
    np.save(tmp_path / "v.npy", np.zeros((4, 4, 4), np.float32))
    code, _, err = run(capsys, "compress", str(tmp_path / "v.npy"), "--level", "1", "-o", str(tmp_path / "v.clw"))
    assert code == 2 and "--level only applies to OME-Zarr images; leave it out for a npy input" in err


def test_info_of_a_time_series_describes_it_and_names_the_refusal(tmp_path, capsys, monkeypatch):
    """trial22: `info fmri4d.nii.gz` was refused, exit 2.  A 4-D NIfTI (.nii, .nii.gz), an ImageJ hyperstack and an
    OME-Zarr image of 3 time points are described from their headers (exit 0, no voxel read): the stored shape with
    its time axis, one volume's shape, spacing and origin as load() places a volume, the time step and its unit, and
    the one line load() refuses the file with."""
    import nibabel
    import tifffile
    import zarr

    affine = np.diag([2.0, 3.0, 4.0, 1.0])
    affine[:3, 3] = (5.0, 6.0, 7.0)
    series = nibabel.Nifti1Image(np.zeros((4, 5, 6, 3), np.int16), affine)
    series.header.set_xyzt_units("mm", "sec")
    series.header["pixdim"][4] = 2.5
    for name in ("f.nii", "f.nii.gz"):
        nibabel.save(series, tmp_path / name)
    tifffile.imwrite(tmp_path / "t.tif", np.zeros((3, 4, 5, 6), np.uint8), imagej=True, resolution=(2.0, 4.0),
                     metadata={"axes": "TZYX", "finterval": 1.5, "spacing": 3.0, "unit": "um"})
    group = zarr.open_group(tmp_path / "t.zarr", mode="w", zarr_format=2)
    group.create_array("0", data=np.zeros((3, 4, 5, 6), np.uint8))
    group.attrs["multiscales"] = [{"axes": [{"name": "t", "unit": "second"}] + [{"name": a} for a in "zyx"],
                                   "datasets": [{"path": "0", "coordinateTransformations": [
                                       {"type": "scale", "scale": [0.5, 3.0, 0.25, 0.5]}]}]}]
    # RAS+ (z, y, x): the NIfTI's k, j, i; its centre (x, y, z) = offset + diag * (n - 1) / 2
    nifti = ([4, 5, 6, 3], [6, 5, 4], [4.0, 3.0, 2.0], [5 + 2 * 1.5, 6 + 3 * 2.0, 7 + 4 * 2.5], 2.5, "sec")
    expected = {"f.nii": nifti, "f.nii.gz": nifti,
                # an ImageJ stack: its axes as stored, z spacing 3, y and x the inverse resolution, origin 0
                "t.tif": ([3, 4, 5, 6], [4, 5, 6], [3.0, 0.25, 0.5], [0.0, 0.0, 0.0], 1.5, "sec"),
                # NGFF: the first voxel at 0, the centre at scale * (n - 1) / 2
                "t.zarr": ([3, 4, 5, 6], [4, 5, 6], [3.0, 0.25, 0.5], [1.25, 0.5, 4.5], 0.5, "second")}
    refusals = {}
    for name in expected:
        with pytest.raises(clwave.FileFormatError) as refused:
            clwave.load(tmp_path / name)
        refusals[name] = str(refused.value)
    monkeypatch.setattr(nibabel.arrayproxy.ArrayProxy, "__getitem__", lambda *a: pytest.fail("a NIfTI voxel read"))
    monkeypatch.setattr(tifffile.TiffFile, "asarray", lambda *a, **k: pytest.fail("a TIFF pixel was read"))
    monkeypatch.setattr(tifffile.TiffPageSeries, "asarray", lambda *a, **k: pytest.fail("a TIFF pixel was read"))
    for name, (stored, shape, spacing, origin, step, unit) in expected.items():
        code, out, err = run(capsys, "info", str(tmp_path / name), "--json")
        assert code == 0, err
        facts = json.loads(out)
        assert (facts["stored_shape"], facts["shape"], facts["spacing"], facts["origin"], facts["channels"]) == \
            (stored, shape, spacing, origin, 1), name
        assert facts["time"] == dict(points=3, step=step, unit=unit, along="time", frame=None), name
        assert facts["refused"] == refusals[name], name
    code, out, err = run(capsys, "info", str(tmp_path / "f.nii.gz"))
    lines = dict(line.split(None, 1) for line in out.splitlines())
    assert code == 0 and lines["stored"] == "4 x 5 x 6 x 3 values of int16, in the file's order of axes, a time " \
        "series", out
    assert lines["spacing"] == "2, 3, 4 mm (x, y, z; --spacing 4,3,2), centre 8, 12, 17, corner voxel " \
                               "(least x, y, z) 5, 6, 7 (RAS+)"
    assert "volume" not in lines
    assert lines["time"] == "3 time points, 2.5 sec apart: --frame K picks one, 0 .. 2 (or -3 .. -1 from the end); " \
        "without it compress, render, progressive, drr and view refuse the file"
    assert refusals["f.nii.gz"].endswith("; clwave reads one volume: pick one, frame=K for K in 0 .. 2 (or -3 .. -1 "
                                         "from the end)")


def test_every_formats_description_has_the_same_keys(tmp_path, capsys):
    """trial22: .nii gave `shape`, `channels`, `spacing_in_file`, .nii.gz `stored_shape`, `resampled` instead.  One
    volume as .nii, .nii.gz, .mgh, .mgz, .nrrd, .npy, .tif, .zarr, .mrc and a DICOM folder: the same JSON keys
    (loaders.DESCRIBED), a fact a format does not give as null; a .clw shares file, format, bytes, shape, channels,
    spacing, origin and obliquity, with its model's own besides."""
    import mrcfile
    import nibabel
    import nrrd
    import tifffile
    import zarr
    from pydicom.uid import generate_uid

    from test_loaders import axial, write_series

    data = (np.arange(4 * 5 * 6).reshape(4, 5, 6) % 7).astype(np.int16)
    for name in ("v.nii", "v.nii.gz"):
        nibabel.save(nibabel.Nifti1Image(data, np.eye(4)), tmp_path / name)
    for name in ("v.mgh", "v.mgz"):
        nibabel.save(nibabel.MGHImage(data, np.eye(4)), tmp_path / name)
    with mrcfile.new(tmp_path / "v.mrc") as mrc:
        mrc.set_data(data)
    nrrd.write(str(tmp_path / "v.nrrd"), data)
    np.save(tmp_path / "v.npy", data)
    tifffile.imwrite(tmp_path / "v.tif", data, photometric="minisblack")
    zarr.open_group(tmp_path / "v.zarr", mode="w", zarr_format=2).create_array("v", data=data)
    (tmp_path / "dicom").mkdir()
    write_series(tmp_path / "dicom", np.random.default_rng(3), axial(0.0, 2.0, 4.0), generate_uid(),
                 ["a.dcm", "b.dcm", "c.dcm"])
    clwave.WaveletVolume.from_volume(clwave.Volume(data.astype(np.float32)), levels=1).save(tmp_path / "v.clw")
    keys = {}
    for name in ("v.nii", "v.nii.gz", "v.mgh", "v.mgz", "v.nrrd", "v.npy", "v.tif", "v.zarr", "v.mrc", "dicom",
                 "v.clw"):
        code, out, err = run(capsys, "info", str(tmp_path / name), "--json")
        assert code == 0, err
        keys[name] = list(json.loads(out))
    clw = set(keys.pop("v.clw"))
    assert len({tuple(k) for k in keys.values()}) == 1, keys
    from clwave.cli.info import GEOMETRY
    from clwave.io.loaders import DESCRIBED

    assert keys["v.nii"] == list(DESCRIBED + GEOMETRY)
    assert set(DESCRIBED + GEOMETRY) & clw == {"file", "format", "bytes", "shape", "channels", "spacing", "origin",
                                               "obliquity", "unit"}
    docs = (Path(__file__).parents[1] / "docs" / "coordinates.md").read_text()
    assert all(f"`{key}`" in docs for key in DESCRIBED + GEOMETRY)  # the keys are listed where `info` is documented


def test_info_prints_world_lengths_without_float_noise(tmp_path, capsys):
    """trial22: an oblique NIfTI's origin printed as `-9.53674e-07, 2.6226e-06, 0` (float32 affine noise).  Text
    rounds world lengths to a millionth of the volume's extent (0 here, 8 voxels of 2 mm rotated 20 degrees about
    z, centred on 0); the JSON keeps the numbers as loaded."""
    import nibabel

    turn = np.radians(20)
    rotation = np.array([[np.cos(turn), -np.sin(turn), 0], [np.sin(turn), np.cos(turn), 0], [0, 0, 1]]) * 2.0
    affine = np.eye(4)
    affine[:3, :3], affine[:3, 3] = rotation, -rotation @ [3.5, 3.5, 3.5]
    nibabel.save(nibabel.Nifti1Image(np.zeros((8, 8, 8), np.float32), affine), tmp_path / "o.nii")
    code, out, _ = run(capsys, "info", str(tmp_path / "o.nii"), "--json")
    origin = json.loads(out)["origin"]
    assert code == 0 and 0 < max(map(abs, origin)) < 1e-6 * 16, origin  # the noise is there, below 16 mm / 1e6
    code, out, _ = run(capsys, "info", str(tmp_path / "o.nii"))
    assert code == 0 and "spacing    2, 2, 2 mm (x, y, z; --spacing 2,2,2), centre 0, 0, 0, corner voxel " \
                             "(least x, y, z) -7, -7, -7 (RAS+)\n" in out, out


def test_info_takes_the_reading_options_and_prints_the_geometry_they_give(tmp_path, capsys):
    """trial24 row 19: `info FOLDER --spacing 10,5,5` was refused; the reading options of the commands (one option
    group) give the spacing, box and unit the commands will use: a folder of slices gets 1, 1, 1 said without it, a
    .raw is described by --shape and --dtype, a value option is named as applied when read; a .clw or no FILE refuses
    them in one line."""
    import tifffile

    (tmp_path / "slices").mkdir()
    for z in range(4):
        tifffile.imwrite(tmp_path / "slices" / f"s{z}.tif", np.zeros((6, 8), np.uint16))
    code, out, err = run(capsys, "info", str(tmp_path / "slices"), "--spacing", "10,5,5", "--subtract", "2000")
    lines = dict(line.split(None, 1) for line in out.splitlines())
    assert code == 0, err
    assert lines["stored"] == "4 x 6 x 8 values of uint16, in the file's order of axes"
    assert lines["volume"] == "8 x 6 x 4 voxels (x, y, z), 1 channel of uint16"
    assert lines["spacing"] == "5, 5, 10 (x, y, z; --spacing 10,5,5 given), centre 0, 0, 0, corner voxel " \
                               "(least x, y, z) -17.5, -12.5, -15"
    assert lines["box"] == "40, 30, 40 (x, y, z) in --spacing's unit"
    assert lines["values"] == "--subtract 2000: applied as the values are read (not read here)"
    code, out, err = run(capsys, "info", str(tmp_path / "slices"), "--json")
    facts = json.loads(out)
    assert (facts["spacing"], facts["box"], facts["unit"], facts["spacing_in_file"]) == ([1.0] * 3, [8, 6, 4], None,
                                                                                        False)
    np.arange(2 * 3 * 4, dtype="<u2").tofile(tmp_path / "v.raw")
    code, out, err = run(capsys, "info", str(tmp_path / "v.raw"), "--shape", "2,3,4", "--dtype", "uint16", "--json")
    facts = json.loads(out)
    assert code == 0 and (facts["shape"], facts["dtype"], facts["reading"]["shape"]) == ([2, 3, 4], "uint16", "2,3,4")
    clwave.WaveletVolume.from_volume(clwave.Volume(np.ones((4, 4, 4))), levels=1).save(tmp_path / "m.clw")
    for argv, needle in (([str(tmp_path / "m.clw"), "--spacing", "1"], "--spacing says how a volume file is read; "),
                         (["--subtract", "1", "--nan", "0"], "--subtract, --nan say how a FILE is read: give the FILE"),
                         ([str(tmp_path / "v.raw")], "is a .raw file: it has no header")):
        code, out, err = run(capsys, "info", *argv)
        assert code == 2 and out == "" and err.count("\n") == 1 and needle in err, err


def test_info_echoes_a_spacing_that_pastes_back_and_refuses_what_render_refuses(tmp_path, capsys):
    """trial26 finding 10: `info --spacing 5000,0.0013888889,0.0013888889` echoed `--spacing 5000,0,0`, and took a
    negative spacing that render refuses.  The echoed option, pasted back, gives the same float32 spacing; a
    non-positive spacing is the one line render gives."""
    np.save(tmp_path / "c.npy", np.zeros((4, 5, 6), np.float32))
    given = "5000,0.0013888889,0.0013888889"
    code, out, err = run(capsys, "info", str(tmp_path / "c.npy"), "--spacing", given)
    lines = dict(line.split(None, 1) for line in out.splitlines())
    assert code == 0, err
    assert lines["spacing"].startswith(f"0.0013888889, 0.0013888889, 5000 (x, y, z; --spacing {given} given)"), out
    code, out, err = run(capsys, "info", str(tmp_path / "c.npy"), "--spacing", "1.5", "--json")
    assert json.loads(out)["spacing_option"] == "--spacing 1.5,1.5,1.5"
    refusals = []
    for command in (["info", str(tmp_path / "c.npy")],
                    ["render", str(tmp_path / "c.npy"), "-o", str(tmp_path / "a.png")]):
        code, out, err = run(capsys, *command, "--spacing", "5000,0.0013888889,-0.0013888889")
        assert code == 2 and out == "" and err.count("\n") == 1, err
        refusals.append(err)
    assert refusals[0] == refusals[1] and "must be positive" in refusals[0]
    assert not (tmp_path / "a.png").exists()
