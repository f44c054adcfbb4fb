"""TIFF stacks (multi-page ``.tif``/``.tiff``) and folders of 2-D TIFF slices through tifffile."""

from __future__ import annotations

import numpy as np

from ...errors import FileFormatError
from .shared import folder_files, read_slices

TIFF_SUFFIXES = (".tif", ".tiff")


def tiff_files(folder):
    return [p for p in folder_files(folder) if p.suffix.lower() in TIFF_SUFFIXES]


def read_tiff(path):
    """A TIFF stack as ``(pages, y, x[, samples])``; one page gives one slice."""
    import tifffile

    with tifffile.TiffFile(path) as tif:
        series = tif.series[0]
        data, axes = series.asarray(), series.axes
        if len(tif.pages) > 1 and len(axes.replace("S", "")) == 2:
            # pages written one at a time form one series each: stack them all
            data, axes = tif.asarray(key=range(len(tif.pages))), "Q" + axes
    if "S" in axes:  # samples per pixel (RGB/RGBA) go last, as channels
        data = np.moveaxis(data, axes.index("S"), -1)
        axes = axes.replace("S", "")
    if len(axes) > 3 or not axes.endswith("YX"):
        raise FileFormatError(
            f"{path} holds a TIFF series with axes {series.axes!r} and shape {series.shape}; "
            "clwave reads one stack of 2-D pages (axes like 'ZYX', optionally with RGB samples)")
    return data if len(axes) == 3 else data[np.newaxis]


def read_tiff_folder(folder, progress_bar):
    """One 2-D TIFF per slice, stacked along z in natural name order."""
    def read_slice(path):
        pages = read_tiff(path)
        if len(pages) != 1:
            raise FileFormatError(f"{path} holds {len(pages)} pages, but a folder of TIFF "
                                  "slices needs one 2-D image per file")
        return pages[0]

    return read_slices(tiff_files(folder), read_slice, "reading TIFF slices", progress_bar)
