"""Zarr stores (v2, v3) and OME-Zarr multiscale images (NGFF 0.4/0.5), read chunk by chunk."""

from __future__ import annotations

import os
import warnings
from fractions import Fraction
from pathlib import Path

import numpy as np

from ...errors import FileFormatError, InputError
from ..images import unit_named
from .shared import FrameOf, TimeSeries, as_array, not_a_file, one_volume, pick_array

ZARR_METADATA = ("zarr.json", ".zarray", ".zgroup")  # v3, v2 array, v2 group

# NGFF axis name -> its role in as_array; units of length in metres (the NGFF list: UDUNITS-2 names)
_NGFF_ROLES = {"z": "s", "y": "s", "x": "s", "c": "c", "t": None}  # t: one time point read (shared.FrameOf)
_SI_PREFIXES = {"yocto": -24, "zepto": -21, "atto": -18, "femto": -15, "pico": -12, "nano": -9, "micro": -6,
                "milli": -3, "centi": -2, "deci": -1, "": 0, "hecto": 2, "kilo": 3, "mega": 6, "giga": 9,
                "tera": 12, "peta": 15, "exa": 18, "zetta": 21, "yotta": 24}
_METRES = {prefix + "meter": Fraction(10) ** power for prefix, power in _SI_PREFIXES.items()} | {
    "angstrom": Fraction(10) ** -10, "inch": Fraction("0.0254"), "foot": Fraction("0.3048"),
    "mile": Fraction("1609.344"), "parsec": Fraction("3.0857e16")}  # exact: 1 micrometer is 1000.0 nanometer
def read_zarr(path, name, level, chunks, fits=None, frame=None):
    """A Zarr array (v2 or v3), or one level of an OME-Zarr multiscale image with its spacing and origin (of a time
    series the time point ``frame``); its chunks decompressed to their size at the most (:mod:`.zarr_bounds`)."""
    from .zarr_bounds import bounded

    with bounded():
        return _read_zarr(path, name, level, chunks, fits, frame)


def _read_zarr(path, name, level, chunks, fits, frame):
    import zarr

    def arrays(group, prefix=""):
        """{name from the store's top: array} of the arrays in ``group`` (at ``prefix``), at any depth; a folder that
        is no node (an array's chunks, where its metadata is no node's) passed over without zarr's warning."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", zarr.errors.ZarrUserWarning)
            return {prefix + n: a for n, a in group.members(max_depth=None) if isinstance(a, zarr.Array)}

    _check_store_files(path)
    node = zarr.open(str(path), mode="r")
    if name is not None:
        if not isinstance(node, zarr.Group):
            raise FileFormatError(f"{path} is one Zarr array, with no array /{name} inside; leave out ':/{name}'")
        if name not in node:
            pick_array(arrays(node), name, path)  # says which arrays there are
        node = node[name]
    where = f"{path}:/{name}" if name else str(path)
    if isinstance(node, zarr.Group):
        attrs = node.attrs.asdict()
        ome = attrs.get("ome", attrs)  # NGFF 0.5 keeps its metadata under "ome"
        if "multiscales" in ome:
            return _read_ome_zarr(node, ome["multiscales"], where, level, chunks, fits, frame)
        node = pick_array(arrays(node, f"{name}/" if name else ""), None, path)[1]
    elif len(node.shape) not in (3, 4):
        raise FileFormatError(f"{where} holds an array of shape {node.shape}; clwave reads a 3-D (z, y, x) or "
                              "4-D (z, y, x, c) array")
    if level is not None:
        raise InputError(f"level= applies to OME-Zarr multiscale images, and {where} is a plain Zarr array; leave "
                         "it out", cli=f"--level applies to OME-Zarr multiscale images, and {where} is a plain "
                                        "Zarr array; leave it out")
    one_volume(frame, where)  # a plain array's axes have no names: (z, y, x[, c])
    return as_array(node, chunks, fits=fits, path=where), None, None


def world_unit(path, name) -> str | None:
    """The world unit of an OME-Zarr image: its x axis's unit (its spacing's: :func:`_read_ome_zarr` converts the z
    and y axes' to it) where it is a world unit (:func:`~clwave.io.images.unit_named`); None for a plain Zarr array,
    an x axis without a unit or with another one."""
    import zarr

    node = zarr.open(str(path), mode="r")
    node = node[name] if name is not None else node
    attrs = node.attrs.asdict() if isinstance(node, zarr.Group) else {}
    ome = attrs.get("ome", attrs)
    multiscales = ome.get("multiscales") if isinstance(ome, dict) else None
    if not multiscales:  # read as a plain array (read_zarr has checked the image's metadata otherwise)
        return None
    axes = _axes(multiscales[0])
    return unit_named(next(a.get("unit") for a in axes if str(a.get("name", "")).lower() == "x"))


def _axes(image) -> list:
    """An OME-Zarr image's axes, each a dict (NGFF 0.3 names them alone)."""
    return [a if isinstance(a, dict) else {"name": a} for a in image.get("axes") or []]


def _check_store_files(store):
    """Refuse a store (a folder) holding a link to a folder (a loop, or a tree elsewhere), a link to a file
    outside it, or a FIFO, socket or device: its chunks would read other files' bytes (``/etc/passwd`` as voxels),
    or ``/dev/zero`` until the memory ran out, or wait for ever.  One walk of the store's names (a link's target is
    resolved, no file is read)."""
    root = Path(store).resolve()
    pending = [root]
    while pending:
        with os.scandir(pending.pop()) as entries:
            for entry in entries:
                if entry.is_symlink():
                    target = Path(entry.path).resolve()
                    if target.is_dir() or not target.is_relative_to(root):
                        raise FileFormatError(f"{store} links {Path(entry.path).relative_to(root)} to {target}, "
                                              "a folder or a file outside the store; clwave reads no files elsewhere "
                                              "for an untrusted store: copy the data into the store")
                    if not target.is_file():
                        raise not_a_file(target)
                elif entry.is_dir():
                    pending.append(entry.path)
                elif not entry.is_file():
                    raise not_a_file(Path(entry.path))


def _read_ome_zarr(group, multiscales, where, level, chunks, fits, frame):
    """Level ``level`` (default 0) of the first OME-Zarr (NGFF 0.4/0.5) multiscale image in ``group``: axes named
    z, y, x, an optional c (channels, moved last) and t (its time point ``frame``, :meth:`.shared.TimeSeries.pick`,
    alone read; of one time point that one); spacing and origin from the scale
    and translation of the level and of the whole image (NGFF puts voxel centres at integer indices, so the
    translation is the first voxel's centre)."""
    def bad(problem):
        return FileFormatError(f"{where}: its OME-Zarr metadata {problem}")

    image = multiscales[0] if isinstance(multiscales, list) and multiscales else None
    if not isinstance(image, dict):
        raise bad(f"holds multiscales {multiscales!r}, not a list of images")
    axes = _axes(image)
    names = [str(a.get("name", "")).lower() for a in axes]
    if not {"z", "y", "x"} <= set(names) <= set(_NGFF_ROLES) or len(set(names)) < len(names):
        raise bad(f"names axes {names}; clwave reads axes z, y, x, with an optional c (channels) and t (time)")
    datasets = image.get("datasets")
    if not isinstance(datasets, list) or not datasets or not all(isinstance(d, dict) and "path" in d
                                                                 for d in datasets):
        raise bad(f"lists datasets {datasets!r}, not the levels' paths")
    if level is None:
        level = 0
    if isinstance(level, (bool, np.bool_)) or not isinstance(level, (int, np.integer)) \
            or not 0 <= level < len(datasets):
        shapes = [tuple(group[d["path"]].shape) if d["path"] in group else "missing" for d in datasets]
        levels = ", ".join(f"{i} {s}" for i, s in enumerate(shapes))
        raise InputError(f"level={level!r} does not exist in the OME-Zarr image {where}; its levels: {levels}",
                         cli=f"--level {level} does not exist in the OME-Zarr image {where}; its levels: {levels}")
    path = datasets[level]["path"]
    if path not in group:
        raise bad(f"names array {path!r} for level {level}, which the store does not hold")
    array = group[path]
    if len(array.shape) != len(names):
        raise bad(f"names {len(names)} axes {names}, but level {level} ({path}) has shape {array.shape}")

    scale, translation = np.ones(len(names)), np.zeros(len(names))
    for transforms in (datasets[level].get("coordinateTransformations") or [],
                       image.get("coordinateTransformations") or []):  # the level's, then the image's
        for transform in transforms:
            kind = transform.get("type") if isinstance(transform, dict) else None
            if kind == "identity":
                continue
            values = np.asarray(transform.get(kind) if kind in ("scale", "translation") else [], float)
            if values.shape != (len(names),) or not np.all(np.isfinite(values)):
                raise bad(f"has the coordinate transformation {transform!r}; clwave reads a scale and a "
                          f"translation of {len(names)} finite numbers each, one per axis {names}")
            if kind == "scale":
                scale, translation = scale * values, translation * values
            else:
                translation = translation + values
    zyx = [names.index(a) for a in "zyx"]
    if np.any(scale[zyx] <= 0):
        raise bad(f"scales the axes {names} by {scale.tolist()}; the z, y, x scale must be positive")
    units = [axes[i].get("unit") for i in zyx]
    if not all(u is None or isinstance(u, str) for u in units):
        raise bad(f"gives the z, y, x axes the units {units}; a unit is a name, e.g. 'micrometer'")
    if len(set(units)) > 1:  # convert to the x axis's unit
        if not all(u in _METRES for u in units):
            raise bad(f"gives the z, y, x axes the units {units}; clwave converts different units of length "
                      f"only ({', '.join(_METRES)})")
        factor = np.array([float(_METRES[u] / _METRES[units[2]]) for u in units])
        scale[zyx], translation[zyx] = scale[zyx] * factor, translation[zyx] * factor

    shape = np.array([array.shape[i] for i in zyx])
    spacing = tuple(float(d) for d in scale[zyx])
    with np.errstate(over="ignore", invalid="ignore"):  # beyond float range: infinite, Volume names the scale
        origin = tuple(float(o) for o in (translation[zyx] + scale[zyx] * (shape - 1) / 2)[::-1])  # its centre, x y z
    points = array.shape[names.index("t")] if "t" in names else 1
    if points > 1:
        t = names.index("t")
        series = TimeSeries(f"{where} holds {points} time points (axis t)", array.shape, array.dtype, points,
                            float(scale[t]), axes[t].get("unit"), array.shape[names.index("c")] if "c" in names else 1)
        series.placed, series.loaded = (spacing, origin, 0.0), tuple(int(n) for n in shape)
        k = series.pick(frame, where)
    else:
        one_volume(frame, where)
        k = 0
    # one time point, alone read: frame's, or the only one
    source = FrameOf(array, names.index("t"), k) if "t" in names else array
    names = [n for n in names if n != "t"]
    data = as_array(source, chunks, "".join(_NGFF_ROLES[n] for n in names), fits, where)
    return data.transpose([names.index(a) for a in "zyxc" if a in names]), spacing, origin
