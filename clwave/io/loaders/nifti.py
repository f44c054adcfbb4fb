"""NIfTI-1/2 files (``.nii``, ``.nii.gz``) through nibabel, in RAS+."""

from __future__ import annotations

import numpy as np

from ...errors import FileFormatError
from .shared import as_array, check_declared_size, to_canonical


def read_nifti(path, chunks):
    """NIfTI-1/2 through nibabel: RGB24/RGBA32 become channels; time series are refused."""
    import nibabel

    image = nibabel.load(path, mmap=False)
    check_declared_size(path, int(image.header["vox_offset"]),
                         int(np.prod(image.shape)) * image.header.get_data_dtype().itemsize, image.shape)
    proxy = image.dataobj  # reads on demand, applying scl_slope / scl_inter
    if proxy.ndim > 3:
        # NIfTI keeps time on the 4th axis and vector components on the 5th
        if proxy.shape[3] != 1 or any(n != 1 for n in proxy.shape[5:]):
            raise FileFormatError(
                f"{path} holds a NIfTI image of shape {proxy.shape}; clwave reads one 3-D "
                "volume (vector components on the 5th axis become channels): extract one "
                "volume first, e.g. with nibabel.funcs.four_to_three")
        proxy = proxy.reshape(proxy.shape[:3] + proxy.shape[4:5])
    data = as_array(proxy, chunks)
    if data.dtype.names:  # RGB24 / RGBA32 structured samples
        data = np.stack([data[name] for name in data.dtype.names], axis=-1)
    return to_canonical(data, image.affine)
