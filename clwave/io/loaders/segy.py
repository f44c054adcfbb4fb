"""SEG-Y files (``.sgy``, ``.segy``), post-stack 3-D seismic, through segyio: time (or depth) down, inlines along x,
crosslines along y (docs/coordinates.md §1)."""

from __future__ import annotations

import os

import numpy as np

from ...device.memory import check_fits
from ...errors import FileFormatError
from .shared import Declared, note, placeable, to_canonical

SEGY_SUFFIXES = (".sgy", ".segy")

#: the two-way velocity a time axis is drawn at (m/s), as OpendTect's Z scale and Petrel's "time as depth" draw it:
#: 2000 m/s makes 1 ms of two-way time 1 m, and a SEG-Y sample interval (µs of time, or a depth's mm) / 1000 metres
REFERENCE_VELOCITY = 2000.0

#: SEG-Y's measurement system (binary header bytes 3255-3256): the world unit of its coordinates
_UNITS = {1: "m", 2: "ft"}


def _segyio(path):
    try:
        import segyio
    except ImportError:
        raise FileFormatError(f"{path} is a SEG-Y file, which clwave reads with segyio, not installed here: pip "
                              f"install segyio in clwave's environment (a clone set up by tools/setup.sh: "
                              f".venv/bin/pip install segyio)") from None
    return segyio


def read_segy(path, fits=None, warn_spacing=True):
    """``(data, spacing, origin)`` of a post-stack SEG-Y cube: its trace count (from the file's size) and samples
    weighed before the traces are sorted or read, a survey segyio cannot sort into inlines x crosslines (or of
    several offsets) refused; the samples as segyio decodes them (IBM floats to float32), on (time, crossline,
    inline) axes with time pointing down (:func:`_survey`); centred on the origin."""
    segyio = _segyio(path)
    survey, cube = _survey(segyio, path, True, fits)
    data, spacing, _, _ = to_canonical(cube, survey["affine"])
    if warn_spacing:
        note(f"{path}: {_z_words(survey)}; --spacing DZ,DY,DX sets another")
    return data, spacing, (0.0, 0.0, 0.0)


def header_facts(path) -> dict:
    """``{"segy": ...}``, what ``clwave info`` says of a SEG-Y file beyond its volume: its inline, crossline and sample
    ranges, sample interval, format code, sorting, the coordinates its bins are measured by and their scalar."""
    survey, _ = _survey(_segyio(path), path)
    return dict(segy={k: v for k, v in survey.items() if k != "affine"} | dict(z=_z_words(survey)))


def world_unit(path) -> str | None:
    """"m" where the binary header's measurement system says metres and the bins are measured by coordinates, else
    None (clwave has no feet)."""
    survey, _ = _survey(_segyio(path), path)
    return "m" if survey["unit"] == "m" and survey["coordinates"] else None


def _z_words(survey) -> str:
    dz = survey["spacing"][0]
    if not survey["interval"]:
        return "no sample interval in its headers: its samples are 1 apart"
    return (f"its samples, {survey['interval']:g} apart in its headers (µs of two-way time, or a depth's mm), are "
            f"{dz:g} apart: time drawn as depth at {REFERENCE_VELOCITY:g} m/s (1 ms a metre), or depth in metres")


def _survey(segyio, path, read=False, fits=None):
    """``(survey, cube)``: what the headers say (the ``affine`` of the cube's axes to RAS+ among them) and, with
    ``read``, the traces as an (inline or crossline as stored, the other, sample) array, weighed (``fits``, then
    the memory) before segyio sorts them."""
    try:
        with segyio.open(path, ignore_geometry=True) as f:  # the binary header; the trace count from the file's size
            samples, counted, dtype, texts = len(f.samples), f.tracecount, f.dtype, f.ext_headers
    except RuntimeError as exc:
        raise FileFormatError(f"{path}: segyio: {exc}: its size is not a whole number of traces of the samples its "
                              f"binary header declares; the file is truncated or its header is wrong") from None
    except ValueError as exc:  # a negative count
        raise FileFormatError(f"{path}: segyio cannot count its traces ({exc}): 2^31 or more (segyio counts in 32 "
                              f"bits), or its binary header is wrong; crop it first") from None
    # the count from the file's size in Python's integers: segyio's wraps at 2^32 (10^10 traces counted 1.4 x 10^9)
    traces = (os.path.getsize(path) - 3600 - 3200 * texts) // (240 + samples * dtype.itemsize)
    if traces != counted:
        raise FileFormatError(f"{path}: its size holds {traces:,} traces of {samples:,} samples, which segyio counts "
                              f"{counted:,} (in 32 bits): crop it first")
    described = None
    if read:  # weighed before segyio sorts the traces: the caller's rule (fits), then the memory
        try:
            if fits is not None:
                fits(traces * samples, 1)
        except Declared as declared:  # describe(): told once the traces are sorted
            described = declared
        else:
            check_fits(traces * samples * (dtype.itemsize + 4 * (dtype != np.float32)), f"reading {path}'s "
                       f"{traces:,} traces of {samples:,} samples", "crop the survey first (segyio, or OpendTect's "
                       "export of a sub-volume); clwave reads a SEG-Y cube whole")
    try:
        f = segyio.open(path)
    except (ValueError, RuntimeError) as exc:
        raise FileFormatError(f"{path}: segyio cannot sort its {traces:,} traces into inlines x crosslines ({exc}); "
                              f"clwave reads a regular post-stack survey, each inline and crossline once: regularise "
                              f"it, or read its traces with segyio.open(path, ignore_geometry=True)") from None
    with f:
        if len(f.offsets) > 1:
            raise FileFormatError(f"{path} holds {len(f.offsets)} offsets a bin (pre-stack gathers); clwave reads "
                                  "post-stack cubes: stack it, or write one offset to a file of its own")
        inline_first = f.sorting == segyio.TraceSortingFormat.INLINE_SORTING
        ilines, xlines = np.asarray(f.ilines), np.asarray(f.xlines)
        dims = (len(ilines), len(xlines)) if inline_first else (len(xlines), len(ilines))
        interval = float(segyio.tools.dt(f, fallback_dt=0.0))
        counts = (len(ilines), len(xlines))
        spacing_il, spacing_xl, mirrored, coordinates, scalar = _bins(segyio, f, path, counts, inline_first)
        dz = interval / 1000 if interval > 0 else 1.0
        steps = {"il": [spacing_il, 0, 0], "xl": [0, -spacing_xl if mirrored else spacing_xl, 0]}
        affine = np.eye(4)
        affine[:3, :3] = np.array([steps["il" if inline_first else "xl"], steps["xl" if inline_first else "il"],
                                   [0, 0, -dz]]).T  # columns: the cube's axes; time points down (inferior)
        affine[:3, 3] = -affine[:3, :3] @ (np.array(dims + (samples,)) - 1) / 2
        if not placeable(affine):
            raise FileFormatError(f"{path}: its bins ({spacing_il:g} by {spacing_xl:g}) and sample interval "
                                  f"({interval:g}) are not a volume's voxels (one over 10000 times another); the "
                                  f"coordinates or their scalar are wrong: give --spacing DZ,DY,DX")
        code = int(f.bin[segyio.BinField.Format])
        survey = dict(inlines=_range(ilines), crosslines=_range(xlines), samples=samples, interval=interval,
                      format=code, format_name=str(f.format), sorting="inline" if inline_first else "crossline",
                      coordinates=coordinates, scalar=scalar, mirrored=mirrored, spacing=[dz, spacing_xl, spacing_il],
                      unit=_UNITS.get(int(f.bin[segyio.BinField.MeasurementSystem])), affine=affine)
        if not read:
            return survey, None
        if described is not None:
            described.shape, described.dtype = dims + (samples,), np.dtype(dtype)
            described.place(described.shape, affine)
            raise described
        return survey, f.trace.raw[:].reshape(dims + (samples,))


def _bins(segyio, f, path, counts, inline_first):
    """``(inline spacing, crossline spacing, mirrored, coordinates, scalar)``: the bins' sizes from the trace headers'
    CDP coordinates (else the source's), scaled by their scalar (bytes 71-72: negative divides), from the first trace
    to the last of the first crossline and inline; ``mirrored``: inlines, crosslines and up are a left-handed frame
    on the map (crosslines are then drawn along -y); 1 each, with a warning, where the headers give no coordinates."""
    field, (n_il, n_xl) = segyio.TraceField, counts
    headers = [f.header[i * n_xl + j if inline_first else j * n_il + i] for i, j in ((0, 0), (n_il - 1, 0),
                                                                                     (0, n_xl - 1))]
    raw = headers[0][field.SourceGroupScalar]
    scalar = 1.0 / abs(raw) if raw < 0 else float(raw or 1)
    for name, keys in (("CDP", (field.CDP_X, field.CDP_Y)), ("source", (field.SourceX, field.SourceY))):
        corners = np.array([[h[k] for k in keys] for h in headers], float) * scalar
        along = corners[1:] - corners[0]
        lengths = np.linalg.norm(along, axis=1) / np.maximum(np.array(counts) - 1, 1)
        if np.all(lengths > 0):
            return *lengths, bool(np.linalg.det(along) < 0), name, raw
    note(f"{path}: no CDP or source coordinates in its trace headers: its bins are taken as 1 by 1; give "
         "--spacing DZ,DY,DX")
    return 1.0, 1.0, False, None, raw


def _range(lines) -> list:
    """``[first, last, step]`` of a survey's line numbers."""
    return [int(lines[0]), int(lines[-1]), int(lines[1] - lines[0]) if len(lines) > 1 else 0]
