"""Headers whose numbers lie at the ends of their range, found by fuzzing every reader (harden20): each refused in one
line naming the problem, with no Python warning beside it, before a voxel is read; and the ends of the world lengths
clwave renders (:data:`~clwave.model.volume.WORLD_RANGE`) rendered as lengths of 1 are, scaled."""

import warnings

import numpy as np
import pytest

from clwave.errors import FileFormatError, InputError
from clwave.io.loaders import describe, load
from clwave.model.volume import WORLD_RANGE, Volume

VOLUME = np.arange(8 * 9 * 10, dtype=np.float32).reshape(8, 9, 10)


def nrrd_file(tmp_path, **fields):
    """A raw little-endian float NRRD of VOLUME (x fastest) with its header's ``fields`` replaced."""
    header = {"type": "float", "dimension": "3", "sizes": "10 9 8", "encoding": "raw", "endian": "little",
              "space": "left-posterior-superior", "space directions": "(1,0,0) (0,1,0) (0,0,1)",
              "space origin": "(0,0,0)"} | {k.replace("_", " "): v for k, v in fields.items()}
    path = tmp_path / "v.nrrd"
    text = "NRRD0004\n" + "".join(f"{k}: {v}\n" for k, v in header.items()) + "\n"
    path.write_bytes(text.encode() + VOLUME.tobytes())
    return path


def refused(call, error, needle):
    """``call()`` raises ``error`` of one line holding ``needle``, with no warning given."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(error) as caught:
            call()
    assert needle in str(caught.value) and "\n" not in str(caught.value)


@pytest.mark.parametrize("fields, needle", [
    # pynrrd casts a size beyond int64 with a RuntimeWarning, to -2^63
    (dict(sizes="99999999999999999999 9 8"), "a number beyond the range of its field"),
    # directions of 1e308: their determinant overflowed (a warning, then 'singular'), as did nibabel's orientation
    (dict(space_directions="(1e308,0,0) (0,1e308,0) (0,0,1e308)"), "outside the world lengths clwave renders"),
    (dict(space_directions="(1e-300,0,0) (0,1e-300,0) (0,0,1e-300)"), "outside the world lengths clwave renders"),
    (dict(space_origin="(1e308,1e308,1e308)"), "outside the world lengths clwave renders"),
])
def test_nrrd_numbers_beyond_their_range_are_one_line(tmp_path, fields, needle):
    path = nrrd_file(tmp_path, **fields)
    refused(lambda: load(path), (FileFormatError, InputError), needle)


def test_nrrd_directions_at_any_scale_are_placed_as_at_one(tmp_path):
    """The orientation, obliquity and voxel sizes of an affine scaled to its columns' largest component: a
    direction of 1e16 and one of 1 give the same array, spacing and origin times 1e16."""
    one = load(nrrd_file(tmp_path, space_directions="(0,-1,0) (2,0,0) (0,0,3)"))
    (tmp_path / "big").mkdir()
    big = load(nrrd_file(tmp_path / "big", space_directions="(0,-1e16,0) (2e16,0,0) (0,0,3e16)"))
    assert np.array_equal(one.data, big.data)
    assert np.allclose(np.array(big.spacing) / 1e16, one.spacing, rtol=1e-12)
    assert np.allclose(np.array(big.origin) / 1e16, one.origin, rtol=1e-12)


@pytest.mark.parametrize("spacing, origin", [(1e-19, 0.0), (2e17, 0.0), (1.0, (0.0, 0.0, 2e18))])
def test_a_volume_outside_the_world_lengths_is_refused(spacing, origin):
    """A spacing below WORLD_RANGE[0], an extent (10 voxels of 2e17) or an origin beyond WORLD_RANGE[1]: the renderers
    divided by zero (1e-308) or overflowed float32 (internal errors)."""
    refused(lambda: Volume(VOLUME, spacing=spacing, origin=origin), InputError, "outside the world lengths")


def test_the_ends_of_the_world_lengths_render_as_lengths_of_one():
    """X-ray line integrals of a volume at spacing WORLD_RANGE[0], and at an extent near WORLD_RANGE[1], are those at
    spacing 1 times the spacing (float32's relative rounding), by splatting and by ray tracing."""
    import clwave
    from clwave.model.wavelet import WaveletVolume

    images = {}
    camera = clwave.Camera(30, 20, size=16)
    for spacing in (1.0, WORLD_RANGE[0], WORLD_RANGE[1] / 10):
        model = WaveletVolume.from_volume(Volume(VOLUME / VOLUME.max(), spacing=spacing), "linear", levels=1)
        images[spacing] = [clwave.splat(model, camera).image,
                           clwave.raytrace(model, camera, absorption=False, tolerance=1e-6 * spacing).image]
    for spacing in (WORLD_RANGE[0], WORLD_RANGE[1] / 10):
        for scaled, plain in zip(images[spacing], images[1.0]):
            assert np.allclose(scaled / spacing, plain, rtol=1e-4, atol=1e-5 * np.abs(plain).max())


def test_a_decompression_bomb_is_weighed_against_the_address_space_limit(tmp_path):
    """A gzip NRRD of 512^3 zero bytes (130 KB on disk, its trailer true) read whole under ``ulimit -v`` with 300 MiB
    to spare: refused before reading as a HostMemoryError naming the room, not read until gzip's MemoryError (then
    called a corrupt file) or the kill; available_bytes weighed the system's memory alone."""
    import gzip
    import subprocess
    import sys

    path = tmp_path / "bomb.nrrd"
    path.write_bytes(b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 512 512 512\nencoding: gzip\n\n"
                     + gzip.compress(bytes(512 ** 3), compresslevel=1))
    script = f"""
import resource
from clwave.device.memory import available_bytes
from clwave.device.memory import HostMemoryError
from clwave.io.loaders import describe, load
mapped = next(int(line.split()[1]) * 1024 for line in open("/proc/self/status") if line.startswith("VmSize:"))
resource.setrlimit(resource.RLIMIT_AS, (mapped + (300 << 20), resource.RLIM_INFINITY))
assert available_bytes() <= 300 << 20, available_bytes()
try:
    load({str(path)!r})
except HostMemoryError as exc:
    print("refused:", exc)
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("refused: reading") and "needs about 640 MiB" in done.stdout


@pytest.mark.parametrize("name", ["v.npy", "v.nhdr"])
def test_a_fifo_is_refused_not_waited_on(tmp_path, name):
    """A FIFO named as a volume file, or as a detached NRRD header's data file: its reader waited for a writer that
    never came (the fuzzer's 60 s timeout); refused in one line naming it."""
    import os
    import subprocess
    import sys

    if name == "v.nhdr":
        (tmp_path / name).write_text("NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n"
                                     "data file: z.raw\n\n")
    fifo = tmp_path / ("z.raw" if name == "v.nhdr" else name)
    os.mkfifo(fifo)
    script = f"from clwave.io.loaders import load\nload({str(tmp_path / name)!r})"
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    last = done.stderr.strip().splitlines()[-1]
    assert last == (f"clwave.errors.FileFormatError: {fifo} is not a regular file (a FIFO, a socket or a device): "
                    "clwave reads volumes from files; copy the data to a file first")


def test_sigterm_while_reading_exits_143_not_as_a_corrupt_file(tmp_path):
    """SIGTERM raises Terminated where the program is; in a loader that was inside ``reading()``, whose
    ``except Exception`` made it 'cannot read ...: Terminated; the file may be truncated or corrupt' (exit 2)."""
    import os
    import signal
    import subprocess
    import sys

    np.save(tmp_path / "v.npy", VOLUME)
    script = f"""
import sys, time
from clwave import cli
from clwave.io.loaders import raw
def slow(*args):
    print("reading", flush=True)
    time.sleep(60)
raw.read_npy = slow
sys.exit(cli.main(["compress", {str(tmp_path / 'v.npy')!r}, "-o", {str(tmp_path / 'out.clw')!r}]))
"""
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env=dict(os.environ))
    while b"reading" not in proc.stdout.readline():
        assert proc.poll() is None
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 143 and err.decode().strip() == "clwave: terminated"


@pytest.mark.parametrize("lie", ["rows", "frames"])
def test_dicom_pixel_data_shorter_than_its_header_declares_is_refused_by_it(tmp_path, rng, lie):
    """A slice declaring 65535 x 65535 pixels over 60 bytes, and an RT Dose file declaring 2^20 frames over its 15:
    refused naming the bytes held and declared, before the declared volume is weighed (it was refused as one needing
    hundreds of GiB, naming chunked reading, which a DICOM input has not) or read; ``clwave info`` says it too."""
    import pydicom
    from pydicom.data import get_testdata_file
    from test_loaders import write_series

    if lie == "rows":
        folder = tmp_path / "series"
        folder.mkdir()
        write_series(folder, rng, [(0, 0, z) for z in range(3)], "1.2.3", ["a.dcm", "b.dcm", "c.dcm"])
        ds = pydicom.dcmread(folder / "b.dcm")
        ds.Rows = ds.Columns = 65535
        ds.save_as(folder / "b.dcm")
        path, needle = folder, "b.dcm holds 60 bytes of pixel data where its header declares 8,589,672,450 (Rows 65535"
    else:
        path = tmp_path / "dose.dcm"
        ds = pydicom.dcmread(get_testdata_file("rtdose.dcm"))
        ds.NumberOfFrames, ds.GridFrameOffsetVector = 1 << 20, list(range(1 << 20))
        ds.save_as(path)
        needle = "holds 6,000 bytes of pixel data where its header declares 419,430,400 (Rows 10, Columns 10, " \
                 "NumberOfFrames 1048576, BitsAllocated 32)"
    refused(lambda: load(path), FileFormatError, needle)
    refused(lambda: describe(path), FileFormatError, needle)


def test_a_dicom_rescale_past_float32_is_named_without_an_overflow_warning(tmp_path, rng):
    """RescaleSlope 1e38 times pixels of 8: the float32 product overflowed with a RuntimeWarning, then the volume was
    refused as holding non-finite voxels; rescaled in float64 a slice at a time, the file is named with its largest
    value."""
    from test_loaders import write_dicom_slice

    for z in range(3):
        write_dicom_slice(tmp_path / f"s{z}", np.full((6, 5), 8), (0.0, 0.0, float(z)), "1.2.3", rescale=(1e38, 0))
    refused(lambda: load(tmp_path, progress_bar=False), InputError, "s0 holds values up to 8e+38, beyond float32's")


def test_dicom_slices_with_bytes_past_their_frame_read_the_frame_their_header_declares(tmp_path, rng):
    """A single-frame slice whose pixel data holds 10 frames' bytes: pydicom returned all 10 (with its warning), and
    the stack was refused as a volume of 10 channels; the header's one frame is read, silently."""
    import pydicom
    from test_loaders import write_series

    stored = write_series(tmp_path, rng, [(0.0, 0.0, float(z)) for z in range(3)], "1.2.3", ["a", "b", "c"])
    ds = pydicom.dcmread(tmp_path / "b")
    ds.PixelData = ds.PixelData * 10
    ds.save_as(tmp_path / "b")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        volume = load(tmp_path, progress_bar=False)
    assert volume.shape == (3, 6, 5) and volume.channels == 1
    assert np.array_equal(volume.data[1], (stored[1] * 2.0 - 1024)[::-1, ::-1])  # rescale (2, -1024), RAS flips


def test_declared_sizes_past_2_to_the_64_are_counted_whole(tmp_path):
    """numpy's product of a shape wraps at 2^64: a NIfTI-2 header of 2^40 voxels an axis declared 0 bytes (2^120 wraps
    to 0) and passed the size check; a .raw of 2^32 x 2^32 x 1 float32 needed 0 bytes, as an empty file holds."""
    import nibabel

    image = nibabel.Nifti2Image(VOLUME, np.eye(4))
    nibabel.save(image, tmp_path / "v.nii")
    data = bytearray((tmp_path / "v.nii").read_bytes())
    data[16:16 + 8 * 4] = np.array([3, 1 << 40, 1 << 40, 1 << 40], "<i8").tobytes()  # dim[0..3]
    (tmp_path / "v.nii").write_bytes(bytes(data))
    refused(lambda: load(tmp_path / "v.nii"), FileFormatError, "its header declares 1099511627776 x 1099511627776 x "
                                                               "1099511627776 voxels")
    (tmp_path / "e.raw").write_bytes(b"")
    refused(lambda: load(tmp_path / "e.raw", shape=(1 << 32, 1 << 32, 1), dtype="float32"), FileFormatError,
            "need 73,786,976,294,838,206,464 bytes")


def test_a_store_of_2_to_the_40_voxels_an_axis_is_refused_before_dask_lists_its_chunks(tmp_path):
    """A Zarr array's metadata declaring 2^40 voxels an axis (no chunk stored): Dask's normalize_chunks listed every
    chunk's size, 2^34 an axis, and ran out of memory (a MemoryError called a corrupt file); refused by the count of
    chunks first, under an address-space limit that the lists would pass."""
    import json
    import subprocess
    import sys

    import zarr

    zarr.create_array(str(tmp_path / "v.zarr"), shape=(8, 9, 10), chunks=(4, 4, 4), dtype="f4")
    meta = json.loads((tmp_path / "v.zarr" / "zarr.json").read_text())
    meta["shape"] = [1 << 40] * 3
    (tmp_path / "v.zarr" / "zarr.json").write_text(json.dumps(meta))
    script = f"""
import resource
from clwave.io.loaders import load
resource.setrlimit(resource.RLIMIT_AS, (3 << 30, resource.RLIM_INFINITY))
try:
    load({str(tmp_path / 'v.zarr')!r})
except Exception as exc:
    print(type(exc).__name__, exc)
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.stdout.startswith("InputError") and "too big for this machine" in done.stdout, done.stdout + done.stderr


def test_dicom_pixel_data_declared_past_the_file_is_refused_before_it_is_read(tmp_path, rng):
    """A slice whose PixelData element declares 4 GiB in a file of 700 bytes: pydicom allocated the 4 GiB to read it
    (a MemoryError called a corrupt file, or the memory taken)."""
    import struct

    from test_loaders import write_series

    write_series(tmp_path, rng, [(0.0, 0.0, float(z)) for z in range(3)], "1.2.3", ["a", "b", "c"])
    data = bytearray((tmp_path / "b").read_bytes())
    at = data.rfind(b"\xe0\x7f\x10\x00")  # (7FE0,0010) OW: tag, VR, 2 reserved bytes, the 4-byte length
    struct.pack_into("<I", data, at + 8, 0xFFFFFFF0)
    (tmp_path / "b").write_bytes(bytes(data))
    refused(lambda: load(tmp_path, progress_bar=False), FileFormatError, "declares 4,294,967,280 bytes of pixel data")


def test_hdf5_volumes_of_hdf5plugin_filters_are_read_and_unknown_ones_refused(tmp_path, monkeypatch):
    """An HDF5 volume compressed with Blosc (hdf5plugin's): its chunks failed one by one as they were read, HDF5
    finding no plugin (an internal error); hdf5plugin registers its filters, so the volume reads as written. A
    filter no one decodes here is refused in one line before a chunk is read."""
    import h5py
    import hdf5plugin
    from h5py import h5z

    import subprocess
    import sys

    with h5py.File(tmp_path / "v.h5", "w") as fh:
        fh.create_dataset("v", data=VOLUME, chunks=(4, 4, 4), **hdf5plugin.Blosc())
    script = (f"import numpy as np\nfrom clwave.io.loaders import load\n"  # a process that has not imported hdf5plugin
              f"print(np.asarray(load({str(tmp_path / 'v.h5')!r}).data).sum())")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and float(done.stdout) == VOLUME.sum(), done.stderr[-300:]
    available = h5z.filter_avail
    monkeypatch.setattr(h5z, "filter_avail", lambda code: code != 32001 and available(code))
    refused(lambda: load(tmp_path / "v.h5"), FileFormatError, "v.h5:/v is filtered by 'blosc' (id 32001), which "
                                                              "neither HDF5 nor hdf5plugin decodes here")


@pytest.mark.parametrize("plant", ["outside", "devzero", "fifo", "folder"])
def test_a_zarr_store_reads_no_file_outside_it(tmp_path, plant):
    """A chunk that is a link to a file outside the store (its bytes read as voxels: /etc/passwd was), to /dev/zero
    (read until the memory ran out), a FIFO (waited on), or a link to a folder (a loop: the group walk recursed):
    refused in one line naming it before the store is opened."""
    import os

    import zarr

    store = tmp_path / "v.zarr"
    zarr.create_array(str(store), shape=(8, 9, 10), chunks=(4, 4, 4), dtype="f4", compressors=None)[...] = VOLUME
    chunk = store / "c" / "0" / "0" / "0"
    (tmp_path / "secret").write_bytes(bytes(256))
    if plant != "folder":
        chunk.unlink()
    {"outside": lambda: os.symlink(tmp_path / "secret", chunk), "devzero": lambda: os.symlink("/dev/zero", chunk),
     "fifo": lambda: os.mkfifo(chunk), "folder": lambda: os.symlink(store, store / "loop")}[plant]()
    needle = "is not a regular file" if plant == "fifo" else "a folder or a file outside the store"
    refused(lambda: load(store), FileFormatError, needle)


def test_dicom_pixel_data_without_a_decoder_here_names_the_packages_that_decode_it(tmp_path, rng, monkeypatch):
    """A series in JPEG-LS (pydicom decodes it with GDCM, a dependency of clwave, pylibjpeg or pyjpegls; taken as
    absent, as pydicom says of them where none is installed): it was 'Unable to decompress ... because all plugins are
    missing dependencies; the file may be truncated or corrupt', read after the volume was weighed."""
    import pydicom
    from pydicom.encaps import encapsulate
    from pydicom.pixels import get_decoder
    from pydicom.uid import JPEGLSLossless
    from test_loaders import write_series

    decoder = type(get_decoder(JPEGLSLossless))
    monkeypatch.setattr(decoder, "is_available", property(lambda decoder: False))
    monkeypatch.setattr(decoder, "missing_dependencies", property(lambda decoder: [
        "gdcm - requires gdcm>=3.0.10", "pylibjpeg - requires pylibjpeg>=2.0 and pylibjpeg-libjpeg>=2.1",
        "pyjpegls - requires numpy and pyjpegls>=1.2"]))
    write_series(tmp_path, rng, [(0.0, 0.0, float(z)) for z in range(3)], "1.2.3", ["a", "b", "c"])
    for name in "abc":
        ds = pydicom.dcmread(tmp_path / name)
        ds.file_meta.TransferSyntaxUID = JPEGLSLossless
        ds.PixelData = encapsulate([bytes(60)])
        ds.save_as(tmp_path / name, enforce_file_format=True)
    refused(lambda: load(tmp_path, progress_bar=False), FileFormatError,
            "holds pixel data in transfer syntax 1.2.840.10008.1.2.4.80 (JPEG-LS Lossless Image Compression), which no "
            "decoder installed here reads (gdcm - requires gdcm")


@pytest.mark.parametrize("offset, value, needle", [
    (40, [1, 10], "NIfTI image of shape (10,); clwave reads 3-D volumes"),  # dim[0] 1
    (70, [4096], "data code 4096 not recognized")])  # datatype
def test_describe_of_a_broken_nifti_header_is_the_readers_one_line(tmp_path, offset, value, needle):
    """describe read the header's facts (nibabel's orientation, shear, intent) before the read checked the header:
    a NIfTI-1 header of 1 dimension, or of an unknown datatype, was an internal error of ``clwave info`` (refuzz22)."""
    import nibabel

    nibabel.save(nibabel.Nifti1Image(VOLUME, np.eye(4)), tmp_path / "v.nii")
    data = bytearray((tmp_path / "v.nii").read_bytes())
    data[offset:offset + 2 * len(value)] = np.array(value, "<i2").tobytes()
    (tmp_path / "v.nii").write_bytes(bytes(data))
    for call in (load, describe):
        refused(lambda: call(tmp_path / "v.nii"), FileFormatError, needle)


@pytest.mark.parametrize("step, units, expect", [
    (np.inf, 10, dict(step=None, unit=None)),  # was "step": Infinity, which no strict JSON parser reads
    (2.0, 0xff, dict(step=2.0, unit=None)),  # unit codes NIfTI does not define: was "KeyError: 7"
    (2.0, 10, dict(step=2.0, unit="sec"))])  # 2 (mm) + 8 (s): the control
def test_a_time_series_step_or_unit_no_header_means_is_none(tmp_path, capsys, step, units, expect):
    """pixdim[4] infinite, or xyzt_units' time code past NIfTI's, of a 4-D NIfTI: described without a step or a
    unit, ``info --json`` strict JSON (refuzz22)."""
    import json

    import nibabel
    from test_cli import run

    nibabel.save(nibabel.Nifti1Image(np.stack([VOLUME, VOLUME], axis=-1), np.eye(4)), tmp_path / "v.nii")
    data = bytearray((tmp_path / "v.nii").read_bytes())
    data[92:96], data[123] = np.float32(step).tobytes(), units  # pixdim[4], xyzt_units
    (tmp_path / "v.nii").write_bytes(bytes(data))
    expect = dict(expect, points=2, along="time", frame=None)
    assert describe(tmp_path / "v.nii")["time"] == expect
    code, out, err = run(capsys, "info", "--json", str(tmp_path / "v.nii"))
    assert code == 0 and json.loads(out, parse_constant=lambda name: pytest.fail(name))["time"] == expect, err


def test_info_of_a_nifti_that_nibabel_fixes_says_nothing_of_the_fix(tmp_path, capsys):
    """A vox_offset of 353 (not a multiple of 16, the data there): nibabel logs a line on every load, which the
    reader quiets, but info's header facts loaded the file again and printed it twice (refuzz22)."""
    import nibabel
    from test_cli import run

    nibabel.save(nibabel.Nifti1Image(VOLUME, np.eye(4)), tmp_path / "v.nii")
    data = bytearray((tmp_path / "v.nii").read_bytes())
    data[108:112] = np.float32(353).tobytes()  # vox_offset
    (tmp_path / "v.nii").write_bytes(bytes(data[:352] + b"\0" + data[352:]))
    code, out, err = run(capsys, "info", str(tmp_path / "v.nii"))
    assert code == 0 and "8 x 9 x 10 voxels" in out and err == "", err
