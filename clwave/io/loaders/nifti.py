"""NIfTI-1/2 files (``.nii``, ``.nii.gz``) through nibabel, in RAS+."""

from __future__ import annotations

import gzip
import logging
import math
import warnings

import numpy as np

from ...device.memory import HostMemoryError
from ...errors import FileFormatError
from .scaling import check_scaling
from .shared import (UNEVEN, Declared, TimeSeries, as_array, check_declared_size, check_float32_range,
                     check_whole, largest_finite, note, one_volume, placeable, proxy_frame, to_canonical)
from .shear import STRAY_VOXELS, straight_grid, unshear


def read_nifti(path, chunks, fits=None, frame=None):
    """NIfTI-1/2 through nibabel: RGB24/RGBA32 become channels; of a time series the time point ``frame``
    (:meth:`.shared.TimeSeries.pick`: refused without it), its samples alone read; a header that cannot
    describe a 3-D volume (its dimensions, a voxel-to-world affine that is not finite or not invertible, more data
    than the file holds) is refused in one line before any voxel is read.  A file without an orientation (sform and
    qform codes 0) is warned of; a sheared affine is resampled onto a straight grid (:mod:`.shear`), read whole."""
    import nibabel

    image = _load(path)
    affine = getattr(image, "affine", None)
    if affine is None:  # e.g. CIFTI-2: data on surfaces and grayordinates, with no voxel grid
        kind = type(image).__name__.removesuffix("Image").replace("Cifti2", "CIFTI-2")
        raise FileFormatError(f"{path} is a {kind} file of shape {image.shape}, not a volume clwave reads (a NIfTI-1/2 "
                              f"image on a voxel grid)")
    if len(image.shape) < 3 or min(image.shape) < 1:
        raise FileFormatError(f"{path} holds a NIfTI image of shape {image.shape}; clwave reads 3-D volumes with at "
                              "least 2 voxels an axis (stack 2-D slices into one first)")
    if not placeable(affine):
        raise FileFormatError(f"{path}: its voxel-to-world affine (sform, qform or pixdim) is not finite or not "
                              f"invertible, or its voxels are more than {UNEVEN:g} times longer along one axis than "
                              "another; fix the header, e.g. with nibabel's set_sform and set_qform")
    if _codes(image.header) == (0, 0):
        note(f"{path} has no orientation (its sform_code and qform_code are 0): nibabel's fallback is assumed, "
             f"{''.join(nibabel.aff2axcodes(affine))} (its first axis to the left, as Analyze's radiological files), "
             f"centred on the origin; its left and right may be swapped: set an sform (nibabel's set_sform) if known")
    least = image.header.single_vox_offset  # the header and its extension flag: 352 bytes (NIfTI-2: 544)
    if image.dataobj.offset < least:  # nibabel takes 0 as it is, and reads the header as voxels
        raise FileFormatError(f"{path}: its vox_offset {image.dataobj.offset} puts its voxels inside its {least}-byte "
                              f"header (a .nii's start at byte {least} or after); correct vox_offset in the header")
    check_declared_size(path, image.dataobj.offset,
                        math.prod(image.shape) * image.header.get_data_dtype().itemsize, image.shape)
    proxy = image.dataobj  # reads on demand, applying scl_slope / scl_inter
    check_scaling(path, ("scl_slope", "scl_inter"), proxy.slope, proxy.inter, image.get_data_dtype())
    # NIfTI keeps time on the 4th axis and vector components on the 5th
    if proxy.ndim > 3 and (proxy.shape[3] != 1 or any(n != 1 for n in proxy.shape[5:])):
        series = TimeSeries(f"{path} holds a NIfTI image of shape {proxy.shape}, {proxy.shape[3]} time points on its "
                            "4th axis", proxy.shape, proxy.dtype, proxy.shape[3], *_time_step(image.header),
                            math.prod(proxy.shape[4:]))
        series.place(proxy.shape[:3], affine)
        k = series.pick(frame, path)
        if math.prod(proxy.shape[4:]) > 1:
            raise FileFormatError(f"{path} holds a NIfTI image of shape {proxy.shape}, a time series of "
                                  f"{math.prod(proxy.shape[4:])} components a voxel, whose time points clwave does "
                                  "not pick (a scalar series' only); write the one you want to a file of its own "
                                  "first (nibabel's dataobj[:, :, :, K])")
        proxy = proxy_frame(proxy, k)
    else:
        one_volume(frame, path)
        if proxy.ndim > 3:
            proxy = proxy.reshape(proxy.shape[:3] + proxy.shape[4:5])
    grid = straight_grid(image.shape, affine)
    sheared = grid.moved > STRAY_VOXELS
    if sheared:  # resampled in memory: read whole, the straight grid weighed first
        chunks = False
        straight = f"{path}'s affine is sheared {grid.degrees:.3g} degrees: the straight grid that holds it is " \
                   f"{' x '.join(map(str, grid.shape))} voxels (i, j, k: the file's axes)"
        fix = "fix the affine where its shear is the header's error, or crop the volume"
        if math.prod(grid.shape) > np.iinfo(np.intp).max // 4:  # past any array: not weighed, nor placed by describe
            raise FileFormatError(f"{straight}, more than an array holds; {fix}")
        try:
            check_whole(path, grid.shape + image.shape[4:5], image.get_data_dtype(), fits, resampled=True)
        except Declared as declared:
            declared.place(grid.shape, grid.affine)
            raise
        except HostMemoryError as exc:  # its own fix (chunks, a subsample) is no fix here: the grid is read whole
            raise HostMemoryError(f"{straight}, which needs {str(exc).split(';')[0].split(' needs ', 1)[-1]}; {fix}") \
                from None
    scaled = proxy.dtype.kind in "iu" and (float(proxy.slope), float(proxy.inter)) != (1.0, 0.0)
    try:
        data = as_array(_ScaledToFloat32(proxy, path) if scaled else proxy, chunks, fits=fits, path=path)
    except Declared as declared:  # describe(): its place from the header (a .nii.gz's, read whole)
        declared.place(proxy.shape[:3], affine)
        raise
    if data.dtype.names:  # RGB24 / RGBA32 structured samples
        data = np.stack([data[name] for name in data.dtype.names], axis=-1)
    if sheared:
        check_float32_range(largest_finite(data), path)  # resampled into float32 (a float file's scl_slope of 3e38)
        note(f"{path}'s affine is sheared {grid.degrees:.3g} degrees (its axes are not at right angles: a CT's gantry "
             f"tilt that dcm2niix left uncorrected writes one): resampled onto a straight grid on the closest RAS "
             f"axes, linearly, the new margins filled with its least value")
        return to_canonical(unshear(data, grid, data.min()), grid.affine)
    return to_canonical(data, affine)


#: the most bytes of NIfTI extensions nibabel may read (it reads every one whole; clwave uses none)
MAX_EXTENSIONS = 64 << 20


def _load(path):
    """``nibabel.load`` without its reports of the header fixes it makes (a log line, a RuntimeWarning): the one line
    that refuses a header is ours; extensions past :data:`MAX_EXTENSIONS` are refused first."""
    import nibabel

    _check_extensions(path)
    log = logging.getLogger("nibabel.global")
    disabled, log.disabled = log.disabled, True
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return nibabel.load(path, mmap=False)
    finally:
        log.disabled = disabled


def _check_extensions(path):
    """Refuse a header whose extension flag is set and whose ``vox_offset`` leaves more than
    :data:`MAX_EXTENSIONS` bytes for extensions: nibabel reads them all into memory, and in a ``.nii.gz`` a few
    kilobytes inflate to gigabytes of them.  The header's first bytes alone are read (a header nibabel does not
    take is left to it)."""
    with (gzip.open if str(path).lower().endswith(".gz") else open)(path, "rb") as fh:
        head = fh.read(_NIFTI2 + 4)
    for order in "<>":
        size = int(np.frombuffer(head[:4], order + "i4")[0]) if len(head) >= 4 else 0
        if size in _VOX_OFFSET and len(head) >= size + 4:
            offset = float(np.frombuffer(head, order + _VOX_OFFSET[size][0], 1, _VOX_OFFSET[size][1])[0])
            room = offset - size - 4
            if head[size] and room > MAX_EXTENSIONS:
                raise FileFormatError(f"{path}: its vox_offset {offset:,.0f} declares {room:,.0f} bytes of "
                                      f"NIfTI extensions, more than the {MAX_EXTENSIONS:,} clwave lets nibabel read "
                                      "(it reads them whole, and clwave uses none): remove them (nibabel: "
                                      "image.header.extensions.clear(), then save)")


_NIFTI2 = 540
#: by sizeof_hdr (NIfTI-1, NIfTI-2), vox_offset's type and place
_VOX_OFFSET = {348: ("f4", 108), _NIFTI2: ("i8", 168)}


def _codes(header) -> tuple:
    return int(header["sform_code"]), int(header["qform_code"])


def _time_step(header) -> tuple:
    """``(step, unit)`` between a time series' volumes: its pixdim[4] and xyzt_units' time unit, ``(None, None)``
    where the header gives no step (0, or no positive finite number); the unit None where the code is none NIfTI
    defines (nibabel's KeyError)."""
    step = float(header["pixdim"][4])
    try:
        unit = header.get_xyzt_units()[1]
    except KeyError:
        unit = "unknown"
    return (step, None if unit == "unknown" else unit) if 0 < step < math.inf else (None, None)


def world_unit(path) -> str | None:
    """The header's spatial unit (xyzt_units): "mm" (unknown too, as NIfTI readers take it), "um" or "m"; None for a
    code NIfTI does not define."""
    try:
        unit = _load(path).header.get_xyzt_units()[0]
    except KeyError:
        return None
    return {"unknown": "mm", "mm": "mm", "micron": "um", "meter": "m"}.get(unit)


def label_intent(path) -> bool:
    """Whether the file's intent is ``NIFTI_INTENT_LABEL`` (its values index labels: a segmentation)."""
    return _load(path).header.get_intent()[0] == "label"


def header_facts(path) -> dict:
    """What ``clwave info`` says of a NIfTI header that :func:`read_nifti` has read or weighed (so checked): the sform
    and qform codes, which affine is used (nibabel's choice: the sform where its code is set, else the qform, else
    none: nibabel's fallback), the stored orientation (``nibabel.aff2axcodes``), whether sform and qform both exist
    and differ, the shear (degrees, 0 where none), the intent and ``scl_slope``/``scl_inter`` where they scale the
    values."""
    import nibabel

    image = _load(path)
    header = image.header
    sform, qform = _codes(header)
    used = "sform" if sform else "qform" if qform else "none"
    affine = header.get_best_affine()
    grid = straight_grid(header.get_data_shape()[:3], affine)
    facts = dict(sform_code=sform, qform_code=qform, affine_from=used, orientation="".join(nibabel.aff2axcodes(affine)),
                 forms_differ=bool(sform and qform and not np.allclose(header.get_sform(), header.get_qform(),
                                                                       atol=1e-3)),
                 sheared=grid.degrees if grid.moved > STRAY_VOXELS else 0.0,
                 intent=header.get_intent()[0])
    slope, inter = float(image.dataobj.slope), float(image.dataobj.inter)  # nibabel moves them from the header
    if (slope, inter) != (1.0, 0.0):
        facts.update(scl_slope=slope, scl_inter=inter)
    return dict(nifti=facts)


class _ScaledToFloat32:
    """A NIfTI proxy of integers with ``scl_slope``/``scl_inter`` whose whole read is scaled (nibabel's own
    ``apply_read_scaling``, in float64) a slab of z at a time into float32 (z: the slowest axis of a volume, and
    within each channel of a vector file): nibabel scales a whole read at once, 8 bytes a voxel beside the integers
    and the float32 copy (docs/benchmarks.md §2).  A chunk read (Dask) is the proxy's own."""

    SLAB_VOXELS = 1 << 22

    def __init__(self, proxy, path):
        self.proxy, self.path = proxy, path
        self.shape, self.dtype, self.ndim = proxy.shape, proxy.dtype, proxy.ndim

    def __getitem__(self, index):
        if index is not Ellipsis:
            return self.proxy[index]
        from nibabel.volumeutils import apply_read_scaling

        raw = self.proxy.get_unscaled()
        out = np.empty(raw.shape, np.float32, order="F")
        axis = min(2, raw.ndim - 1)  # z: a vector file's last axes are its channels, each a whole volume
        step = max(1, self.SLAB_VOXELS * raw.shape[axis] // max(1, raw.size))
        top = 0.0
        for k in range(0, raw.shape[axis], step):
            slab = (slice(None),) * axis + (slice(k, k + step),)
            part = apply_read_scaling(raw[slab], np.asanyarray(self.proxy.slope), np.asanyarray(self.proxy.inter))
            top = max(top, largest_finite(part))
            if top <= float(np.finfo(np.float32).max):  # past it, the read is refused below (by the largest value)
                out[slab] = part
        check_float32_range(top, self.path)
        return out
