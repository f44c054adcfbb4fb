"""Volume: a (z, y, x[, c]) float32 array with physical voxel spacing, in memory (numpy) or chunked
(a Dask array, never read whole: docs/chunked.md).

Conventions (docs/coordinates.md): host arrays are ``(z, y, x)`` or ``(z, y, x, c)``;
``spacing = (dz, dy, dx)`` in world units; ``origin = (x, y, z)`` is the world
position of the volume's centre.  Voxel ``(i, j, k)`` sits at world
``origin + ((k - (nx-1)/2) dx, (j - (ny-1)/2) dy, (i - (nz-1)/2) dz)``.
"""

from __future__ import annotations

import numpy as np

from ..errors import ClwaveWarning, InputError, finite_number, flag, reals, warn_outside
from .dataarray import from_data_array, is_data_array, is_dataset
from .geometry import WORLD_RANGE, axis_turn, fine_to_world, turned, world_to_fine
from .labels import looks_like_labels

MAX_CHANNELS = 4
#: the most voxels (of the smallest spacing) an origin's coordinates lie from 0: float64 places the volume's corners
#: within 1e-4 of a voxel there (2⁻⁵³ of 1e12); at 1e16 voxels they round to other voxels (a content box of one point)
ORIGIN_VOXELS = 1e12
#: A classified volume's premultiplied colour never exceeds its alpha: :func:`warn_straight_colour` tells one whose
#: colour does by more than STRAIGHT_MARGIN of its largest value in more than STRAIGHT_SHARE of its voxels above that
#: margin in some channel (on an even sample of at most STRAIGHT_SAMPLE): a photo's straight colour and alpha given as
#: classified (the trial's shell and cube: all of them).  A classified model's reconstruction rings past its alpha in
#: at most 3 % of them at that margin (hydrogen, cubic and quintic, 1 % and 5 % kept; 12 % to 48 % at 1/255).
STRAIGHT_MARGIN, STRAIGHT_SHARE, STRAIGHT_SAMPLE = 0.05, 0.1, 1 << 20


def _computed(values):
    """``values`` (a list or tuple of arrays), Dask ones computed together in one pass."""
    if any(is_dask(v) for v in values):
        import dask

        return list(dask.compute(*values))
    return list(values)


class Volume:
    """A scalar or multi-channel volume on a regular grid.

    Parameters
    ----------
    data : array_like, shape (nz, ny, nx) or (nz, ny, nx, c)
        Voxel values; converted to float32 once, here (a float32 C-ordered array is kept as it is, not copied).
        ``c`` is 1 to 4 (scalar, RGB, RGBA or classified ``(q_R, q_G, q_B, alpha)``).  A masked array with masked
        voxels is refused: give them a value first (``data.filled(0)``).  A Dask array is kept lazy (docs/chunked.md).
        An xarray DataArray is read by its dims' names, not their order (z, y, x and a channel dim; CF names such as
        lat, lon, depth; :mod:`clwave.model.dataarray`), its data kept as it is (over Dask, lazy); its axes whose
        coordinates decrease are reversed, and its evenly spaced coordinates give ``spacing``, ``origin`` and
        ``unit`` where those are not given (docs/coordinates.md §1).
    spacing : float or 3 floats
        Voxel size ``(dz, dy, dx)`` in world units (default 1.0, or a DataArray's coordinates'; given, it wins over
        them, with a warning where they differ, and their origin and unit are not used either).
    origin : 3 floats
        World position ``(x, y, z)`` of the volume centre (default 0, or a DataArray's coordinates' centre), after
        ``orientation=`` turns the axes.
    orientation : str, optional
        The directions ``data``'s x, y and z index axes (array axes 2, 1, 0) point to, three of nibabel's axis codes
        (``"LPS"``; ``"RAI"``: z down, a seismic cube's time axis), as :func:`clwave.load` takes them: the volume is
        turned into RAS+ (its axes flipped and permuted, ``spacing`` with them), as a medical file is
        (docs/coordinates.md §1).  None (default): the array's axes are the world's.
    subtracted : float
        The value subtracted from the input's values to make ``data`` (``clwave.load(subtract=)``,
        ``--subtract``; default 0): transfer functions are written in the input's units, and are applied to
        ``data`` shifted by it (:meth:`TransferFunction.shifted`, docs/coordinates.md §1).
    obliquity : float
        Degrees between the volume's axes and the scanner's of the file it was read from (default 0): an oblique
        acquisition is kept on its voxel grid, its axes taken as the world's (docs/coordinates.md §1), so a pose
        is relative to them; a cone beam's view of it warns (:meth:`clwave.ConeBeam.view`).
    photo : bool
        Whether 2 to 4 channels are a photo's straight colour and alpha (an RGBA image stack; ``clwave.load`` sets it
        for PNG, JPEG and TIFF colour samples), which a transfer function classifies (the ``photo`` preset:
        ``TransferFunction.preset("photo").classify(vol)``, its own colour and alpha); False (default): 4 channels
        are a classified ``(q_R, q_G, q_B, alpha)``, premultiplied, rendered as they are.  A model of 4 channels
        whose colour exceeds its alpha (no premultiplied colour does) warns, naming ``photo=True``
        (:func:`warn_straight_colour`, docs/model.md §5).
    labels : bool, optional
        Whether the values are labels (a segmentation; NIfTI's ``NIFTI_INTENT_LABEL``), or a label map's
        classification (:meth:`TransferFunction.classify` keeps it); None (default): told from ``data`` as given
        (:func:`~clwave.model.labels.looks_like_labels`: few non-negative integers forming regions).  Its model of a
        wavelet of order above 1 warns (docs/model.md §5).
    unit : str, optional
        The world unit, the length of ``spacing``'s 1 where it is known: "m", "cm", "mm", "um", "nm" or "A" (ångström)
        (:data:`clwave.io.images.UNIT_METRES`; :func:`clwave.load`: the file's); None (default): unknown.  Kept by
        the model and its ``.clw`` file, and written into a picture's resolution (pHYs, TIFF tags).  A DataArray's:
        its coordinates' ``units`` where they name one.
    stored_dtype : numpy dtype, optional
        The type of the input's values as stored (:func:`clwave.load`: the file's, before float32); None (default):
        ``data``'s own.  ``clwave compress`` weighs its file against the input's size in it.
    provenance : dict, optional
        Where the values were read from, ``{"file": path, "frame": K or None}`` (:func:`clwave.load` sets it: the
        file and the time point ``frame=`` picked); None (default): not read from a file.  Kept by the model and its
        ``.clw`` file, and shown by ``clwave info`` (docs/chunked.md §4).
    modality : str or dict, optional
        What acquired the values, ``{"name": DICOM Modality ("CT", "MR", "PT"...), "units": their units (RescaleType
        "HU", a PET's Units "BQML") or None}``, or its name alone (:func:`clwave.load` sets it from a DICOM series);
        None (default): not known.  Kept by the model and its ``.clw`` file, shown by ``clwave info``; a CT preset
        on a volume of another modality warns (docs/model.md §5).

    Examples
    --------
    >>> v = Volume(np.ones((4, 5, 6)), spacing=(2.0, 1.0, 1.0))
    >>> v.shape, v.channels, v.spacing
    ((4, 5, 6), 1, (2.0, 1.0, 1.0))
    """

    def __init__(self, data, spacing=None, origin=None, subtracted=0.0, obliquity=0.0, labels=None,
                 stored_dtype=None, unit=None, photo=False, provenance=None, modality=None, orientation=None):
        if is_dataset(data):
            raise InputError(f"volume data is an xarray Dataset of the variables {', '.join(map(str, data.data_vars))}"
                             f"; give one of them, a DataArray: Volume(ds[name])")
        if is_data_array(data):
            data, spacing, origin, unit = from_data_array(data, spacing, origin, unit)
        lazy = is_dask(data)
        if np.ma.is_masked(data):  # numpy.asarray would take the masked voxels' values as they are
            raise InputError(f"volume data is a masked array with {np.ma.count_masked(data)} masked voxel(s), whose "
                             f"stored values would be rendered; give them a value first, e.g. data.filled(0)")
        try:
            arr = data if lazy else np.asarray(data)
        except (ValueError, TypeError) as exc:  # e.g. a ragged nested list
            raise InputError(f"volume data must be a rectangular array (z, y, x[, c]): {exc}") from None
        if arr.dtype.kind not in "biuf":
            raise InputError(
                f"volume dtype {arr.dtype} is not numeric; give integers or floats "
                "(complex, object and string data cannot be rendered)")
        if lazy and np.isnan(arr.shape).any():  # e.g. d[d[:, 0, 0] > 0]: its chunks are known once computed
            raise InputError(f"this Dask array's shape {arr.shape} is unknown (chunks of unknown size, e.g. from a "
                             f"boolean index); give dask_array.compute_chunk_sizes() first")
        if arr.ndim not in (3, 4):
            raise InputError(
                f"volume must be 3-D (z, y, x) or 4-D (z, y, x, c), got shape {arr.shape}")
        if arr.ndim == 4 and not 1 <= arr.shape[3] <= MAX_CHANNELS and 1 in arr.shape[:3]:
            axis = arr.shape.index(1)  # never squeezed here: which axes are z, y, x is the user's to say
            what = (f"volume data of shape {tuple(arr.shape)} has a length-1 axis {axis} (e.g. a FITS cube's "
                    f"degenerate Stokes axis), and {arr.shape[3]} values in its last, which (z, y, x, c) reads as "
                    f"channels (1 to {MAX_CHANNELS}); drop it: data[{':, ' * axis}0] (numpy.squeeze(data, "
                    f"axis={axis}))")
            raise InputError(what, cli=f"{what}, written to a file of its own")
        if arr.ndim == 4 and not 1 <= arr.shape[3] <= MAX_CHANNELS:
            what = (f"volume has {arr.shape[3]} channels in its last axis; 1 to {MAX_CHANNELS} are supported (scalar, "
                    f"RGB, RGBA); axis order is (z, y, x, c), and a time series (t, z, y, x) is rendered one time "
                    f"point at a time")
            raise InputError(f"{what}: give one, e.g. data[t]", cli=f"{what}: write one to a file (or dataset) of "
                                                                    f"its own")
        shape = arr.shape[:3]
        if min(shape) < 2:
            raise InputError(
                f"volume shape {shape} (z, y, x) has an axis shorter than 2 voxels; "
                "every axis needs at least 2 voxels")
        if arr.ndim == 4 and arr.shape[3] == 1:
            arr = arr[..., 0]
        self.spacing = _triple(1.0 if spacing is None else spacing, "spacing")
        if min(self.spacing) <= 0:
            raise InputError(f"spacing {self.spacing} must be positive (dz, dy, dx)")
        if orientation is not None:  # turned into RAS+ as load(orientation=) turns a file, before the C-ordered copy
            arr, self.spacing = turned(arr, self.spacing, axis_turn(orientation))
            shape = arr.shape[:3]
        self.stored_dtype = np.dtype(arr.dtype if stored_dtype is None else stored_dtype)
        # told from the values as given (integers), before they are float32; a chunked volume's are not read here
        self.labels = (not lazy and looks_like_labels(arr)) if labels is None else flag(labels, "labels")
        if lazy:  # each chunk is converted and checked when it is read
            arr = (arr if arr.ndim == 3 else arr.rechunk({3: -1})).map_blocks(checked_float32, dtype=np.float32)
        else:
            arr = checked_float32(arr)
        self.data = arr
        origin = tuple(float(o) for o in reals(0.0 if origin is None else origin, "origin", 3,
                                               "one number or three (x, y, z)", one=True))
        check_placement(shape, self.spacing, origin)  # first: a huge spacing makes an infinite origin
        if not np.all(np.isfinite(origin)):
            raise InputError(f"origin {origin} must be finite (x, y, z)")
        self.origin = origin
        self.subtracted = finite_number(subtracted, "subtracted")
        self.obliquity = finite_number(obliquity, "obliquity")
        if not 0 <= self.obliquity <= 90:
            raise InputError(f"obliquity={obliquity!r} must be degrees from 0 to 90")
        from ..io.images import check_unit

        self.unit = check_unit(unit)
        self.photo = flag(photo, "photo") and self.channels > 1
        self.provenance = check_provenance(provenance)
        self.modality = check_modality(modality)

    @property
    def shape(self) -> tuple:
        """Grid shape ``(nz, ny, nx)`` without the channel axis."""
        return tuple(int(s) for s in self.data.shape[:3])

    @property
    def chunked(self) -> bool:
        """True when the data is a Dask array (read chunk by chunk, docs/chunked.md)."""
        return is_dask(self.data)

    @property
    def channels(self) -> int:
        return 1 if self.data.ndim == 3 else int(self.data.shape[3])

    @property
    def extent(self) -> tuple:
        """World size of the voxel box ``(nx dx, ny dy, nz dz)``, x first."""
        (nz, ny, nx), (dz, dy, dx) = self.shape, self.spacing
        return (nx * dx, ny * dy, nz * dz)

    def channel(self, c: int) -> np.ndarray:
        """Channel ``c`` as a (nz, ny, nx) array (channel 0 of a scalar volume is its data)."""
        return self.data if self.data.ndim == 3 else self.data[..., c]

    def voxel_to_world(self, index_zyx) -> np.ndarray:
        """World points (N, 3) as (x, y, z) of fractional voxel indices (N, 3) as (i, j, k)."""
        return fine_to_world(index_zyx, 0, self.shape, self.spacing, self.origin)

    def world_to_voxel(self, points_xyz) -> np.ndarray:
        """Fractional voxel indices (N, 3) as (i, j, k) of world points (N, 3) as (x, y, z)."""
        return world_to_fine(points_xyz, 0, self.shape, self.spacing, self.origin)

    def content_mask(self):
        """(nz, ny, nx) bool: the voxels with a non-zero value in some channel (a Dask array for a
        chunked volume)."""
        return content_of(self.data)

    def content_box(self, mask=None):
        """World (x, y, z) corners ``(lo, hi)`` of the voxels with a non-zero value, each voxel a
        box of its spacing (``None`` when every voxel is zero); ``mask``: :meth:`content_mask`, when
        the caller has it."""
        return self._box(_computed(self._projections(mask)))

    def value_range(self):
        """``(min, max)`` of a scalar volume's values in the input's units (its data plus :attr:`subtracted`), the range
        post-classification clamps the model's field to (docs/raytracing.md §10); None for several channels."""
        ends = self._ends()
        return None if ends is None else self._range(_computed(ends))

    def content_box_and_value_range(self, client, progress_bar=None):
        """:meth:`content_box` and :meth:`value_range` from one pass over a chunked volume's data on ``client``, a
        task a block, which its bar counts (docs/chunked.md §5)."""
        import dask

        from ..schedulers import stream

        blocks = self.data.to_delayed()
        corners = np.stack(np.meshgrid(*(np.cumsum((0,) + c[:-1]) for c in self.data.chunks), indexing="ij"), -1)
        projections = [np.zeros(n, bool) for n in self.shape]
        scalar, ends = self.channels == 1, []
        tasks = (dask.delayed(_block_pass)(block, scalar) for block in blocks.ravel())
        found = stream(client, tasks, desc="content", progress_bar=progress_bar)
        for corner, (hits, block_ends) in zip(corners.reshape(-1, self.data.ndim), found):
            for axis, hit in enumerate(hits):
                projections[axis][corner[axis]:corner[axis] + len(hit)] |= hit
            ends.append(block_ends)
        value_range = self._range((min(lo for lo, _ in ends), max(hi for _, hi in ends))) if scalar else None
        return self._box(projections), value_range

    def _projections(self, mask):
        return projected(self.content_mask() if mask is None else mask)

    def _box(self, projections):
        ends = []
        for axis in range(3):
            hit = np.flatnonzero(projections[axis])
            if not len(hit):
                return None
            ends.append((hit[0] - 0.5, hit[-1] + 0.5))
        corners = self.voxel_to_world(np.array(ends).T)  # (2, 3): the first and the last corner
        return corners.min(axis=0), corners.max(axis=0)

    def _ends(self):
        return None if self.channels != 1 else (self.data.min(), self.data.max())

    def _range(self, ends):
        return tuple(float(e) + self.subtracted for e in ends)

    def __repr__(self):
        subtracted = f", subtracted={self.subtracted:g}" if self.subtracted else ""
        return (f"Volume(shape={self.shape}, channels={self.channels}, "
                f"spacing={self.spacing}, origin={self.origin}{subtracted})")


def warn_straight_colour(volume: Volume):
    """A :class:`ClwaveWarning` where ``volume``, 4 channels in memory not marked :attr:`Volume.photo`, looks like a
    photo's straight colour and alpha rather than the premultiplied colour it is taken for: its colour exceeds its
    alpha (:data:`STRAIGHT_SHARE`, :data:`STRAIGHT_MARGIN`), which a classification never gives (an opaque, too
    bright picture, what is inside hidden).  Warned, not refused: 4 channels may be any four quantities to splat."""
    if volume.channels != 4 or volume.photo or volume.chunked:
        return
    voxels = volume.data.reshape(-1, 4)
    sample = voxels[::max(1, len(voxels) // STRAIGHT_SAMPLE)]  # a view, whatever the volume's size
    alpha, colour = sample[:, 3], sample[:, :3].max(axis=1)
    margin = STRAIGHT_MARGIN * max(float(alpha.max()), float(colour.max()), 0.0)
    seen = np.count_nonzero((colour > margin) | (alpha > margin))
    over = np.count_nonzero(colour > alpha + margin)
    if not over or over <= STRAIGHT_SHARE * seen:
        return
    line = (f"this 4-channel volume's colour exceeds its alpha in {over / seen:.0%} of its voxels, "
            f"which no classified (premultiplied) colour does: it looks like a photo's straight colour and alpha, "
            f"rendered as classified it is too bright and opaque; give {{}} (docs/model.md §5)")
    warn_outside(ClwaveWarning(
        line.format("Volume(data, photo=True) and classify it, TransferFunction.preset('photo').classify(vol)"),
        cli=line.format("--tf photo")))


def is_dask(data) -> bool:
    """True for a Dask array (without importing Dask when it is not in use)."""
    return type(data).__module__.startswith("dask.")


def checked_float32(block) -> np.ndarray:
    """``block`` (the volume, or a chunk of it) as C-ordered float32, checked finite (:func:`checked_block`): a value
    beyond float32's range becomes inf there, and is named, not warned about by NumPy's cast."""
    with np.errstate(over="ignore"):
        return checked_block(np.ascontiguousarray(block, dtype=np.float32))


def checked_block(block: np.ndarray) -> np.ndarray:
    """``block`` (float32) when all its values are finite; else the InputError of a volume with NaN/Inf."""
    finite = np.isfinite(block)
    if not finite.all():
        bad = int(block.size - np.count_nonzero(finite))
        what = (f"volume has {bad} non-finite voxel value(s) (NaN/Inf, or beyond float32's range of +-3.4e38, which "
                f"clwave computes in)")
        raise InputError(f"{what}; replace them first (NaN as no data: load(path, nan=0.0); else e.g. "
                         f"numpy.nan_to_num(data)), or rescale the values",
                         cli=f"{what}; give NaN voxels a value with --nan VALUE (no data, e.g. 0), and write Inf or "
                             f"values out of float32's range again")
    return block


def _block_pass(block, scalar):
    """A block's content projected on each axis, and a scalar's ``(min, max)``: a task of
    :meth:`Volume.content_box_and_value_range`."""
    return projected(content_of(block)), (block.min(), block.max()) if scalar else None


def projected(occupied):
    """Each axis' projection of a (nz, ny, nx) bool ``occupied``: where along it some voxel is."""
    return [occupied.any(axis=tuple(a for a in range(3) if a != axis)) for axis in range(3)]


def content_of(data):
    """(nz, ny, nx) bool of the voxels with a non-zero value in some channel of ``data`` (z, y, x[, c])."""
    return (data != 0).any(axis=3) if data.ndim == 4 else data != 0


def frame_problem(shape, spacing, origin) -> tuple[str, str] | None:
    """What is wrong with a ``spacing`` (dz, dy, dx; positive) and ``origin`` (x, y, z; finite) of a ``shape``
    (z, y, x) volume outside :data:`WORLD_RANGE`, or with an origin more than :data:`ORIGIN_VOXELS` voxels from 0,
    and the argument to change ("spacing" or "origin"), or None."""
    low, high = WORLD_RANGE
    if min(spacing) < low or max(float(d) * n for d, n in zip(spacing, shape)) > high or max(map(abs, origin)) > high:
        return (f"spacing {tuple(spacing)} (dz, dy, dx) and origin {tuple(origin)} (x, y, z) of a "
                f"{' x '.join(map(str, shape))} volume lie outside the world lengths clwave renders (a voxel at least "
                f"{low:g}, the volume's extent and its origin at most {high:g})", "spacing")
    if max(map(abs, origin)) > ORIGIN_VOXELS * min(spacing):
        return (f"origin {tuple(origin)} (x, y, z) lies more than {ORIGIN_VOXELS:g} voxels from 0 (spacing "
                f"{tuple(spacing)}, dz, dy, dx), where float64 rounds its voxels' positions (to whole voxels at "
                f"1e16)", "origin")
    return None


def check_placement(shape, spacing, origin):
    """Refuse a ``spacing`` and ``origin`` of a ``shape`` volume that :func:`frame_problem` refuses, naming the
    argument to change (``Volume``'s, and ``clwave info``'s of a header that places the volume)."""
    problem = frame_problem(shape, spacing, origin)
    if problem and problem[1] == "origin":
        raise InputError(f"{problem[0]}; give origin= nearer its voxels (the volume's centre; 0 centres it)",
                         cli=f"{problem[0]}; write the file with an origin nearer its voxels, or read it in Python "
                             f"with clwave.load(path, origin=(0, 0, 0))")
    if problem:
        raise InputError(f"{problem[0]}; give spacing= in other units", cli=f"{problem[0]}; give --spacing in other "
                                                                            f"units")


def check_provenance(source) -> dict | None:
    """``provenance`` (:class:`Volume`'s) as ``{"file": str, "frame": a whole number (as ``load`` took it: -1 the last)
    or None}``, or None; InputError (a ValueError) otherwise: a ``.clw`` header's is said as the file's fault."""
    if source is None:
        return None
    frame = source.get("frame") if isinstance(source, dict) else None
    if not (isinstance(source, dict) and set(source) == {"file", "frame"} and isinstance(source["file"], str)
            and (frame is None or (isinstance(frame, int) and not isinstance(frame, bool)))):
        raise InputError(f"provenance {source!r} is not {{'file': path, 'frame': a whole number or None}}")
    return dict(file=source["file"], frame=frame)


def check_modality(modality) -> dict | None:
    """``modality`` (:class:`Volume`'s) as ``{"name": str, "units": str or None}`` (a name alone: no units), or None;
    InputError (a ValueError) otherwise: a ``.clw`` header's is said as the file's fault."""
    if modality is None or isinstance(modality, dict) and set(modality) == {"name", "units"} and \
            isinstance(modality["name"], str) and modality["name"] and isinstance(modality["units"], (str, type(None))):
        return None if modality is None else dict(modality)
    if isinstance(modality, str) and modality:
        return dict(name=modality, units=None)
    raise InputError(f"modality {modality!r} is not a DICOM Modality ('CT', 'MR'...) or {{'name': it, 'units': str "
                     f"or None}}")


def _triple(value, name) -> tuple:
    arr = reals(value, name, 3, "one number or three (dz, dy, dx)", one=True)
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} ({', '.join(f'{a:g}' for a in arr)}) must be finite")
    return tuple(float(a) for a in arr)
