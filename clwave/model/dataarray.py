"""xarray DataArrays as volumes (docs/coordinates.md §1): their axes put in clwave's (z, y, x[, c]) order by their
dimension names, the spacing, origin and unit taken from their coordinates, the data kept as it is (a Dask array stays
a Dask array, read chunk by chunk).  Duck-typed (``dims``, ``coords``, ``data``): xarray is not imported."""

from __future__ import annotations

import numpy as np

from ..errors import ClwaveWarning, InputError, reals, warn_outside

#: the dimension names (any case) of each axis: clwave's own, then the usual CF coordinate names
AXIS_NAMES = {"z": ("z", "depth", "height", "altitude"), "y": ("y", "lat", "latitude"),
              "x": ("x", "lon", "longitude"), "c": ("c", "channel", "channels", "band", "bands", "rgb", "rgba",
                                                    "colour", "color")}
#: evenly spaced: every coordinate within this share of a step of its place on the line from the first to the last
EVEN = 1e-3


def is_dataset(data) -> bool:
    """True for an xarray Dataset (variables, not one array)."""
    return hasattr(data, "data_vars") and hasattr(data, "dims")


def is_data_array(data) -> bool:
    """True for an xarray DataArray (or another array with named dims and coordinates)."""
    return all(hasattr(data, name) for name in ("dims", "coords", "data")) and not is_dataset(data)


def from_data_array(da, spacing, origin, unit) -> tuple:
    """``(data, spacing, origin, unit)`` of DataArray ``da``: its data in (z, y, x[, c]) order by its dims' names
    (:data:`AXIS_NAMES`, a coordinate's CF ``axis``; xarray's default names ``dim_0``, ... by position), each axis
    whose coordinate decreases reversed; where ``spacing`` is None, the spacing, centre and unit of its evenly spaced
    coordinates (a ``positive="down"`` or ``depth`` coordinate's axis points down), and ``origin`` and ``unit`` as
    given where they are not None.  A ``spacing`` given that the coordinates contradict warns."""
    dims = tuple(str(d) for d in da.dims)
    data = da.data
    if len(dims) not in (3, 4):  # Volume names the shape
        return data, spacing, origin, unit
    roles = _roles(da, dims)
    order = [roles.index(r) for r in "zyxc" if r in roles]
    data = data if order == list(range(len(dims))) else data.transpose(order)
    names = [dims[roles.index(axis)] for axis in "zyx"]
    lines = [_line(da, name, spacing is None) for name in names]
    have = [line is not None for line in lines]
    if spacing is None and any(have) and not all(have):
        missing = [name for name, h in zip(names, have) if not h]
        raise InputError(f"the DataArray has coordinates on some of its axes but not on {', '.join(missing)}, so its "
                         f"spacing is unknown: give them all (da.assign_coords({missing[0]}=...)) or spacing=(dz, dy, "
                         f"dx)")
    reverse = tuple(slice(None, None, -1 if h and line[-1] < line[0] else 1) for line, h in zip(lines, have))
    if any(r.step == -1 for r in reverse):
        data = data[reverse]
    if not all(have):
        return data, spacing, origin, unit
    lines = [line[r] for line, r in zip(lines, reverse)]
    if spacing is not None:
        _warn_other_spacing(spacing, lines, names)
        return data, spacing, origin, unit
    steps = [_step(line, name) for line, name in zip(lines, names)]
    centre = tuple(float(line[0] + line[-1]) / 2 for line in lines[::-1])  # x, y, z
    return data, tuple(steps), centre if origin is None else origin, _unit(da, names) if unit is None else unit


def _roles(da, dims) -> list:
    """The axis (z, y, x or c) each of ``dims`` names; an InputError where one names none or two name one."""
    if all(d == f"dim_{i}" for i, d in enumerate(dims)):  # xarray's names for dims not named: by position
        return list("zyxc"[:len(dims)])
    roles = []
    for d in dims:
        axis = next((a for a, names in AXIS_NAMES.items() if d.lower() in names), None)
        cf = str(_attrs(da, d).get("axis", "")).lower()
        roles.append(axis or (cf if cf in ("z", "y", "x") else None))
    unknown = [d for d, r in zip(dims, roles) if r is None]
    if unknown:
        known = "; ".join(f"{a}: {', '.join(n)}" for a, n in AXIS_NAMES.items())
        raise InputError(f"the DataArray's dims {dims} name no axis clwave knows in {', '.join(map(repr, unknown))} "
                         f"(it reads z, y, x and an optional channel dim c by name, any case: {known}): rename it "
                         f"(da.rename({unknown[0]}='z')), select one of it (da.isel({unknown[0]}=0)), or give the "
                         f"array in (z, y, x[, c]) order by position, da.transpose(...).data, with spacing=")
    for axis in "zyxc":
        named = [d for d, r in zip(dims, roles) if r == axis]
        if len(named) > 1:
            raise InputError(f"the DataArray's dims {', '.join(map(repr, named))} both name its {axis} axis: rename "
                             f"one (da.rename(...)) or select one of it (da.isel(...))")
    missing = [axis for axis in "zyx" if axis not in roles]
    if missing:
        raise InputError(f"the DataArray's dims {dims} name no {' or '.join(missing)} axis; clwave renders a 3-D "
                         f"volume (z, y, x[, c]): name its dims so (da.rename(...))")
    return roles


def _attrs(da, dim) -> dict:
    return dict(getattr(da.coords[dim], "attrs", {})) if dim in da.coords else {}


def _line(da, dim, needed):
    """The 1-D coordinate of ``dim`` as float64, pointing up (CF's ``positive="down"``, and ``depth`` unless its
    ``positive`` is "up", negated); None where it has none, or (not ``needed`` for the spacing) none of numbers."""
    if dim not in da.coords:
        return None
    values = np.asarray(da.coords[dim].values)
    if values.ndim != 1 or values.dtype.kind not in "iuf" or not np.all(np.isfinite(values)):
        if not needed:
            return None
        raise InputError(f"the DataArray's {dim} coordinate ({values.dtype}) is not finite numbers, no lengths: give "
                         f"spacing=(dz, dy, dx)")
    positive = str(_attrs(da, dim).get("positive", "down" if dim.lower() == "depth" else "up")).lower()
    return -values.astype(np.float64) if positive == "down" else values.astype(np.float64)


def _even_step(line) -> tuple:
    """``(step, even)``: the step of ``line`` from its first coordinate to its last, and whether every coordinate lies
    within :data:`EVEN` of a step of its place on that line."""
    step = float(line[-1] - line[0]) / max(len(line) - 1, 1)
    return step, bool(np.abs(line - (line[0] + step * np.arange(len(line)))).max() <= EVEN * step)


def _step(line, name) -> float:
    """The step of an evenly spaced (:data:`EVEN`), increasing ``line``; an InputError otherwise."""
    if len(line) < 2:
        return 1.0  # one voxel: Volume refuses its shape
    step, even = _even_step(line)
    if not step > 0 or not even:
        steps, fix = np.diff(line), "give spacing=(dz, dy, dx) to place its voxels evenly"
        if not steps.any():  # one value: no length to take, nothing to resample
            raise InputError(f"the DataArray's {name} coordinate has one value at every voxel, no step: {fix}")
        raise InputError(f"the DataArray's {name} coordinate is not evenly spaced (steps from {steps.min():.6g} to "
                         f"{steps.max():.6g}) and clwave renders a regular grid: resample it (e.g. "
                         f"da.interp({name}=numpy.linspace(...))), or {fix}")
    return step


def _unit(da, names):
    """The world unit of the coordinates of ``names`` (their ``units``), None where it is no length clwave knows; an
    InputError where they differ."""
    units = [_attrs(da, name).get("units") for name in names]
    if len(set(map(str, units))) > 1:
        raise InputError(f"the DataArray's z, y, x coordinates ({', '.join(names)}) are in different units "
                         f"({', '.join(map(repr, units))}): give spacing=(dz, dy, dx) in one unit, and unit=")
    from ..io.images import unit_named

    return unit_named(units[0]) if units[0] is not None else None


def _warn_other_spacing(spacing, lines, names):
    """Warn where ``spacing`` (given) is not the step of the coordinates ``lines`` (z, y, x)."""
    given = reals(spacing, "spacing", 3, "one number or three (dz, dy, dx)", one=True)
    steps, evens = zip(*map(_even_step, lines))
    steps, even = np.array(steps), all(evens)
    if not even or not np.allclose(given, steps, rtol=EVEN, atol=0):
        coords = f"steps {tuple(float(f'{s:.6g}') for s in steps)}" if even else "uneven steps"
        warn_outside(ClwaveWarning(f"spacing={tuple(float(g) for g in given)} given places the DataArray's voxels, "
                                   f"not its {', '.join(names)} coordinates ({coords}), nor their centre and unit; "
                                   f"leave spacing= out to place the volume by its coordinates"))
