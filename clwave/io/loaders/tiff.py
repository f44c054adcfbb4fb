"""TIFF stacks (multi-page ``.tif``/``.tiff``) and folders of 2-D TIFF slices through tifffile."""

from __future__ import annotations

import numpy as np

from ...errors import FileFormatError
from .shared import check_whole, folder_files, log, read_slices

TIFF_SUFFIXES = (".tif", ".tiff")


def tiff_files(folder):
    return [p for p in folder_files(folder) if p.suffix.lower() in TIFF_SUFFIXES]


def read_tiff(path, fits=None, stack=True):
    """A TIFF stack as ``(pages, y, x[, samples])``; without ``stack`` (a slice of a folder) one page gives one
    slice, with it one 2-D image is refused.  With ``stack``, one page of 3 or 4
    planar samples that tifffile wrote from a 3-D array of that shape (``tifffile.imwrite`` of a 3 or 4 x Y x X
    stack stores it as an RGB(A) image) is read as that many slices, with a warning: a 2-D image is no volume.
    The series' declared size is weighed (:func:`check_whole`) before its pages are read."""
    import tifffile

    with tifffile.TiffFile(path) as tif:
        series = tif.series[0]
        shape, axes = tuple(series.shape), series.axes
        written = tif.shaped_metadata[0].get("shape") if tif.is_shaped and tif.shaped_metadata else None
        planes = stack and len(tif.pages) == 1 and axes == "SYX" and list(shape) == written
        if planes:
            log.warning("%s is one TIFF page of %d planar samples, as tifffile.imwrite writes a %s array: read as "
                        "%d slices (write a stack with photometric='minisblack' to say so)", path, shape[0],
                        " x ".join(map(str, shape)), shape[0])
            axes = "QYX"
        pages = len(tif.pages) > 1 and len(axes.replace("S", "")) == 2  # pages written one at a time: one series each
        if pages:
            shape, axes = (len(tif.pages),) + shape, "Q" + axes
        if "S" in axes:  # samples per pixel (RGB/RGBA) go last, as channels
            shape = tuple(n for n, a in zip(shape, axes) if a != "S") + (shape[axes.index("S")],)
        spatial = axes.replace("S", "")
        if len(spatial) > 3 or not spatial.endswith("YX"):
            raise FileFormatError(
                f"{path} holds a TIFF series with axes {series.axes!r} and shape {series.shape}; "
                "clwave reads one stack of 2-D pages (axes like 'ZYX', optionally with RGB samples)")
        if stack and len(spatial) == 2:
            raise FileFormatError(f"{path} holds one 2-D image ({' x '.join(map(str, series.shape))}, axes "
                                  f"{series.axes!r}), not a stack of slices; write a volume one page a slice, e.g. "
                                  f"tifffile.imwrite(path, volume, photometric='minisblack')")
        check_whole(path, shape if len(spatial) == 3 else (1,) + shape, series.dtype, fits)
        data = tif.asarray(key=range(len(tif.pages))) if pages else series.asarray()
    if "S" in axes:
        data = np.moveaxis(data, axes.index("S"), -1)
    return data if len(spatial) == 3 else data[np.newaxis]


def read_tiff_folder(folder, progress_bar, fits=None):
    """One 2-D TIFF per slice, stacked along z in natural name order."""
    def read_slice(path):
        pages = read_tiff(path, stack=False)
        if len(pages) != 1:
            raise FileFormatError(f"{path} holds {len(pages)} pages, but a folder of TIFF "
                                  "slices needs one 2-D image per file")
        return pages[0]

    return read_slices(tiff_files(folder), read_slice, "reading TIFF slices", progress_bar, fits)
