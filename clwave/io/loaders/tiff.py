"""TIFF stacks (multi-page ``.tif``/``.tiff``) and TIFF slices (of a folder, ``slices``) through tifffile."""

from __future__ import annotations

import lzma
import math
import zlib
from functools import partial

import numpy as np

from ...device.memory import check_fits
from ...errors import FileFormatError
from ..images import unit_named
from .inflate import inflated
from .shared import (Declared, FrameOf, OnDemand, TimeSeries, as_array, by_size, check_whole, log, no_spacing, note,
                     one_volume)

TIFF_SUFFIXES = (".tif", ".tiff")
#: micrometres per unit of an OME-TIFF's PhysicalSize (OME's UnitsLength; its default is the micrometre)
OME_MICROMETRES = {"pm": 1e-6, "Å": 1e-4, "nm": 1e-3, "µm": 1.0, "um": 1.0, "mm": 1e3, "cm": 1e4, "m": 1e6}

#: the decompressors of tifffile's own decoders (its fallbacks where imagecodecs is not installed), which decompress a
#: strip or tile whole whatever its size (a few kilobytes that inflate to gigabytes): :func:`_bound_decoders`
UNBOUNDED = {"zlib_decode": zlib.decompressobj, "lzma_decode": lzma.LZMADecompressor}
#: the codes of TIFF's compressions that tifffile decodes so: zlib (Adobe, PKZIP, PixTIFF), LZMA
BOUNDED_CODES = (8, 32946, 50013, 34925)

#: the most bytes of a TIFF's first strip or tile decoded to try its codec before a read (:func:`_check_decodable`)
DECODE_TRIAL = 1 << 24


def world_unit(path) -> str | None:
    """The unit of a TIFF stack's spacing: "um" for an OME-TIFF (:func:`_ome_spacing` converts to micrometres), an
    ImageJ stack's own ``unit`` where it is a length (:func:`~clwave.io.images.unit_named`), None otherwise (no
    spacing in the file)."""
    import tifffile

    with tifffile.TiffFile(path) as tif:
        if tif.is_ome:
            return "um"
        unit = (tif.imagej_metadata or {}).get("unit")
    return unit_named(unit)


def colour_samples(path) -> bool:
    """Whether a TIFF's first series holds colour samples (RGB, RGBA: its axes' S), not an OME-TIFF's channels."""
    import tifffile

    with tifffile.TiffFile(path) as tif:
        return "S" in tif.series[0].axes


def read_tiff(path, fits=None, stack=True, chunks=False, warn_spacing=False, frame=None):
    """``(data, spacing, origin)``: a TIFF stack as ``(pages, y, x[, samples])``, its spacing ``(dz, dy, dx)`` where
    it is an OME-TIFF (:func:`_ome_spacing`) or an ImageJ stack (:func:`_imagej_spacing`), else None (with a warning
    where ``warn_spacing``: none was given), and an OME-TIFF's origin (:func:`_ome_origin`; else None); without
    ``stack`` (a slice of a folder) one page gives one slice, with it one 2-D image is refused.  With ``stack``,
    one page of 3 or 4 planar samples that tifffile wrote from a 3-D array of that shape (``tifffile.imwrite`` of a
    3 or 4 x Y x X stack stores it as an RGB(A) image) is read as that many slices, and a series of more channels
    than clwave models and no z axis (``tifffile.imwrite`` of a 3-D array with ``imagej=True`` or ``ome=True`` and
    no ``axes``: 'CYX') as that many slices, each with a warning: a 2-D image is no volume.
    ``chunks`` (:func:`.shared.as_array`'s; None: by size): whole, the series' declared size weighed
    (:func:`check_whole`) before its pages are read, or a Dask array whose chunks tifffile reads from the file
    (:func:`_read_region`), in whole multiples of its pages (or strips, or tiles).  Of a series with a time axis T
    (an ImageJ hyperstack, an OME-TIFF) the time point ``frame`` (:meth:`.shared.TimeSeries.pick`), its own pages
    alone read, whole or chunk by chunk."""
    import tifffile

    _bound_decoders()
    with tifffile.TiffFile(path) as tif:
        series = tif.series[0]
        shape, axes = tuple(series.shape), series.axes
        written = tif.shaped_metadata[0].get("shape") if tif.is_shaped and tif.shaped_metadata else None
        planes = stack and len(tif.pages) == 1 and axes == "SYX" and list(shape) == written
        if planes:
            note(f"{path} is one TIFF page of {shape[0]} planar samples, as tifffile.imwrite writes a "
                 f"{' x '.join(map(str, shape))} array: read as {shape[0]} slices (write a stack with "
                 f"photometric='minisblack' to say so)")
            axes = "QYX"
        if stack and axes == "CYX" and shape[0] > 4:
            note(f"{path} holds a TIFF series with axes 'CYX' and shape {series.shape}: {shape[0]} channels and no z "
                 f"axis, as tifffile.imwrite writes a 3-D array with imagej=True or ome=True and no axes; read as "
                 f"{shape[0]} slices (a Z stack): write it with metadata={{'axes': 'ZYX'}} to say so")
            axes = "ZYX"
        pages = len(tif.pages) > 1 and len(axes.replace("S", "")) == 2  # pages written one at a time: one series each
        if pages:
            shape, axes = (len(tif.pages),) + shape, "Q" + axes
        # samples per pixel (RGB/RGBA), or an OME-TIFF's channels, go last as the volume's channels
        channel = "S" if "S" in axes else "C" if "C" in axes else None
        if channel == "C" and shape[axes.index("C")] > 4:
            first_four = ":, " * series.axes.index("C") + ":4"  # the C axis of what imread returns, wherever it is
            raise FileFormatError(
                f"{path} holds a TIFF series with axes {series.axes!r} and shape {series.shape}: "
                f"{shape[axes.index('C')]} channels, where clwave models at most 4; write the channels you want "
                f"(up to 4) to a TIFF of their own, e.g. tifffile.imwrite('part.ome.tif', "
                f"tifffile.imread({str(path)!r})[{first_four}], metadata={{'axes': {series.axes!r}}})")
        stored = shape  # the axes as the file gives them, the channels where they are
        if channel:
            shape = tuple(n for n, a in zip(shape, axes) if a != channel) + (shape[axes.index(channel)],)
        spatial = axes.replace(channel or "S", "")
        timed = len(spatial) == 4 and spatial[0] == "T" and spatial.endswith("YX")  # an ImageJ hyperstack, an OME-TIFF
        if timed:  # one time point read, from its own pages: the series as if it were that one volume
            k = _time_series(tif, path, shape).pick(frame, path)
            spatial, shape = spatial[1:], shape[1:]
        else:
            one_volume(frame, path)
        if len(spatial) > 3 or not spatial.endswith("YX"):
            raise FileFormatError(
                f"{path} holds a TIFF series with axes {series.axes!r} and shape {series.shape}; "
                "clwave reads one stack of 2-D pages (axes like 'ZYX', optionally with RGB samples or up to 4 "
                "channels, 'ZCYX'): save one such stack, e.g. with tifffile.imwrite(path, volume, "
                "metadata={'axes': 'ZCYX'})")
        if stack and len(spatial) == 2:
            raise FileFormatError(f"{path} holds one 2-D image ({' x '.join(map(str, series.shape))}, axes "
                                  f"{series.axes!r}), not a stack of slices; write a volume one page a slice, e.g. "
                                  f"tifffile.imwrite(path, volume, photometric='minisblack')")
        _check_decodable(series, path)
        spacing = _ome_spacing(tif, path) if tif.is_ome else _imagej_spacing(tif, path)  # from the metadata alone
        if spacing is None and warn_spacing:
            no_spacing(path)
        origin = _ome_origin(tif, path, spacing or (1.0,) * 3, shape[:3], k if timed else 0) \
            if tif.is_ome and len(spatial) == 3 else None
        chunks = by_size(chunks, shape) if stack else False
        try:
            if chunks is not False or timed:  # through tifffile's Zarr store: a time point's pages alone, or chunks
                roles = "".join("c" if a == channel else "s" for a in axes)
                own = (1,) + stored[1:] if pages else _store_chunks(series, path)
                source = OnDemand(partial(_read_region, str(path), pages), stored, series.dtype, own)
                if timed:
                    t = axes.index("T")
                    source, roles, axes = FrameOf(source, t, k), roles[:t] + roles[t + 1:], axes[:t] + axes[t + 1:]
                data = as_array(source, chunks, roles, fits=fits, path=path)
                return (np.moveaxis(data, axes.index(channel), -1) if channel else data), spacing, origin
            check_whole(path, shape if len(spatial) == 3 else (1,) + shape, series.dtype, fits)
        except Declared as declared:  # describe's (clwave info): the axes as stored, spacing and origin the header's
            declared.loaded = declared.shape[:3]
            if spacing is not None:
                declared.placed = (spacing, (0.0, 0.0, 0.0) if origin is None else origin, 0.0)
            raise
        data = tif.asarray(key=range(len(tif.pages))) if pages else series.asarray()
    if channel:
        data = np.moveaxis(data, axes.index(channel), -1)
    return (data if len(spatial) == 3 else data[np.newaxis]), spacing, origin


def _bound_decoders():
    """Replace, in tifffile's table of decoders, each of its own decoders that ignores the size of the strip or tile
    it is given (:data:`UNBOUNDED`) by one that decompresses that many bytes and refuses the byte past them
    (:func:`.inflate.inflated`); imagecodecs' decoders, where installed, decode into that size themselves."""
    import tifffile

    table = tifffile.TIFF.DECOMPRESSORS
    for code in BOUNDED_CODES:
        decode = table[code] if code in table else None
        if getattr(decode, "__module__", None) == "tifffile._imagecodecs" and decode.__name__ in UNBOUNDED:
            table._codecs[code] = partial(_decode_bounded, UNBOUNDED[decode.__name__])  # the table's cache


def _decode_bounded(new, data, out):
    """tifffile's decoder: a strip or tile ``data`` of ``out`` bytes decoded, decompressed by ``new``'s."""
    return inflated(data, new, None, out, "a compressed strip or tile")


def _check_decodable(series, path):
    """Refuse pages compressed by a codec tifffile has no decoder for here (LZW, JPEG, ... need imagecodecs), and
    pages whose first strip or tile (of at most DECODE_TRIAL bytes, stored and decoded) it cannot decode (other
    codecs, samples of 12 bits), before anything else is read: ``clwave info`` refuses them as a read does."""
    import tifffile

    page = series.keyframe
    if page.compression not in tifffile.TIFF.DECOMPRESSORS:
        raise FileFormatError(f"{path} holds {page.compression.name}-compressed pages, which tifffile decodes only "
                              f"with the imagecodecs package: install it (pip install imagecodecs), or write the stack "
                              f"uncompressed or with compression='zlib'")
    decoded = math.prod(page.chunks) * page.samplesperpixel * (page.dtype.itemsize if page.dtype else 8)
    if page.databytecounts and 0 < page.databytecounts[0] <= DECODE_TRIAL and decoded <= DECODE_TRIAL:
        page.parent.filehandle.seek(page.dataoffsets[0])
        try:
            page.decode(page.parent.filehandle.read(page.databytecounts[0]), 0)
        except (ImportError, NotImplementedError) as exc:
            raise FileFormatError(f"{path}: tifffile cannot decode its pages ({page.compression.name} compression, "
                                  f"{page.bitspersample}-bit samples) here: {exc}; install imagecodecs (pip install "
                                  f"imagecodecs), or write the stack uncompressed with samples of 8, 16 or 32 bits") \
                from None


def _store_chunks(series, path) -> tuple:
    """The chunks of ``series`` as tifffile's Zarr store gives them (a page, a strip or a tile; each decoded whole
    for any part of it), one of which must fit in memory: refused before anything is read where it does not."""
    import zarr

    with series.aszarr() as store:
        own = zarr.open(store, mode="r").chunks
    check_fits(math.prod(own) * series.dtype.itemsize, f"one {' x '.join(map(str, own))} {series.dtype} page, strip "
               f"or tile of {path} (decoded whole for any part of it)", "write the TIFF in smaller strips or tiles")
    return own


def _read_region(path, pages, index):
    """``index`` of a TIFF stack, the file opened anew: its first series through tifffile's Zarr store (only the
    pages, strips or tiles that ``index`` covers are read and decoded), or of ``pages`` written one at a time (one
    series each) those of the index's z range."""
    import tifffile
    import zarr

    _bound_decoders()  # in a worker process too
    with tifffile.TiffFile(path) as tif:
        if pages:
            return np.stack([tif.pages[z].asarray()[index[1:]] for z in range(len(tif.pages))[index[0]]])
        with tif.series[0].aszarr() as store:
            return zarr.open(store, mode="r")[index]


def _time_series(tif, path, shape) -> TimeSeries:
    """The refusal of a TIFF series whose first axis (``shape``: its axes in the volume's order, channels last) is
    time, read without ``frame``, with its spacing and origin from its metadata and its time step: an OME-TIFF's
    ``TimeIncrement`` (in its ``TimeIncrementUnit``, s where none is given), an ImageJ hyperstack's ``finterval`` (in
    its ``tunit``, sec)."""
    series = tif.series[0]
    if tif.is_ome:
        pixels = _ome_pixels(tif)
        step, unit = pixels.get("TimeIncrement"), pixels.get("TimeIncrementUnit", "s")
    else:
        meta = tif.imagej_metadata or {}
        step, unit = meta.get("finterval"), meta.get("tunit", "sec")
    refused = TimeSeries(f"{path} holds a TIFF series with axes {series.axes!r} and shape {series.shape}: "
                         f"{shape[0]} time points (axis T)", series.shape, series.dtype, shape[0],
                         None if step is None else float(step), None if step is None else unit, math.prod(shape[4:]))
    spacing = _ome_spacing(tif, path) if tif.is_ome else _imagej_spacing(tif, path)
    if spacing is not None:
        origin = _ome_origin(tif, path, spacing, shape[1:4]) if tif.is_ome else (0.0, 0.0, 0.0)
        refused.placed = (spacing, origin, 0.0)
    refused.loaded = shape[1:4]
    return refused


def _ome_pixels(tif) -> dict:
    """The ``Pixels`` element of an OME-TIFF's first image, as a dict."""
    import tifffile

    image = tifffile.xml2dict(tif.ome_metadata).get("OME", {}).get("Image", {})
    return (image[0] if isinstance(image, list) else image).get("Pixels", {})


def _ome_origin(tif, path, spacing, shape, t=0):
    """``(x, y, z)`` in micrometres of the centre of an OME-TIFF's first image, whose first voxel sits at its first
    plane's ``PositionX/Y`` and at the ``PositionZ`` of its plane ``TheZ`` 0, each in its own unit
    (``Position*Unit``, micrometres where none is given), 0 where none is given: where NGFF's translation puts an
    OME-Zarr's first voxel (docs/coordinates.md §1); of a time series, of the planes of its time point ``t`` (``TheT``,
    where they give it).  A position that is no finite length is 0 there, with a warning."""
    planes = _ome_pixels(tif).get("Plane") or []
    planes = [p for p in (planes if isinstance(planes, list) else [planes]) if isinstance(p, dict)]
    planes = [p for p in planes if p.get("TheT", 0) == t] or planes
    first = planes[0] if planes else {}
    z0 = next((p for p in planes if p.get("TheZ", 0) == 0), first)
    corner, bad = [], []
    for axis, plane in (("X", first), ("Y", first), ("Z", z0)):
        value, unit = plane.get(f"Position{axis}"), plane.get(f"Position{axis}Unit", "µm")
        try:
            p = float(value) * OME_MICROMETRES[unit] if value is not None else 0.0
        except (KeyError, TypeError, ValueError):
            p = np.nan
        if not np.isfinite(p):
            bad.append(f"{axis.lower()} ({value!r} {unit!r})")
            p = 0.0
        corner.append(p)
    if bad:
        note(f"{path}: its OME plane position along {', '.join(bad)} is not a finite length in "
             f"{', '.join(OME_MICROMETRES)}; taken as 0 there")
    half = (np.array(shape[::-1], float) - 1) / 2 * np.array(spacing[::-1], float)  # first voxel to centre, (x, y, z)
    return tuple(float(c) for c in np.array(corner) + half)


def _ome_spacing(tif, path):
    """``(dz, dy, dx)`` in micrometres of an OME-TIFF's first image: its ``PhysicalSizeZ/Y/X``, each in its own unit
    (``PhysicalSize*Unit``, micrometres where none is given); an axis without a size is 1 (logged), one whose
    size or unit is no length clwave knows is 1 with a warning; None where it gives no size at all."""
    pixels = _ome_pixels(tif)
    if not any(f"PhysicalSize{axis}" in pixels for axis in "ZYX"):
        return None
    spacing, bad = [], []
    for axis in "ZYX":
        size, unit = pixels.get(f"PhysicalSize{axis}"), pixels.get(f"PhysicalSize{axis}Unit", "µm")
        try:
            d = float(size) * OME_MICROMETRES[unit] if size is not None else 1.0
        except (KeyError, TypeError, ValueError):
            d = np.nan
        if not (np.isfinite(d) and d > 0):
            bad.append(f"{axis.lower()} ({size!r} {unit!r})")
            d = 1.0
        elif size is None:
            log.info("%s: its OME metadata gives no PhysicalSize%s; taken as 1 micrometre", path, axis)
        spacing.append(d)
    if bad:
        note(f"{path}: its OME PhysicalSize along {', '.join(bad)} is not a positive length in "
             f"{', '.join(OME_MICROMETRES)}; taken as 1 micrometre there: give spacing= (--spacing DZ,DY,DX) for the "
             f"true one")
    return tuple(spacing)


def _imagej_spacing(tif, path):
    """``(dz, dy, dx)`` of an ImageJ stack in its ``unit`` (e.g. micron, no conversion): ``spacing=`` of its
    metadata along z and the inverse of its X/YResolution (pixels per unit) along x and y; None for other
    TIFF files, whose resolution tags are print densities (dots per inch), not voxel sizes, and for an ImageJ stack
    with no calibration (no ``spacing``, no ``unit``, a resolution of 1 pixel per unit: ImageJ's "pixel")."""
    meta = tif.imagej_metadata
    if not meta or not ("spacing" in meta or "unit" in meta or tif.pages[0].get_resolution() != (1, 1)):
        return None
    per_unit = np.array(tif.pages[0].get_resolution()[::-1], float)  # (y, x)
    with np.errstate(divide="ignore"):
        spacing = (float(meta.get("spacing", 1.0)),) + tuple(float(d) for d in 1 / per_unit)
    bad = [a for a, d in zip("zyx", spacing) if not (np.isfinite(d) and d > 0)]
    if bad:  # each axis on its own: a bad z spacing leaves the resolution's y and x
        note(f"{path}: its ImageJ spacing along {', '.join(bad)} (dz, dy, dx = {', '.join(f'{d:g}' for d in spacing)})"
             f" is not positive and finite; taken as 1 there: give spacing= (--spacing DZ,DY,DX) for the true one")
    return tuple(1.0 if a in bad else d for a, d in zip("zyx", spacing))

