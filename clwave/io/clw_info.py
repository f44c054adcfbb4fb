"""What a ``.clw`` file holds, from its header and its members' sizes, without reading a coefficient (``clwave info
FILE``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..model.bspline import WAVELET_ORDERS
from ..model.transfer import TransferFunction
from .clw import open_clw
from .clw_header import check_dataset, checked_header, checked_values, member_rows

_WAVELETS = {order: name for name, order in WAVELET_ORDERS.items()}


def describe_clw(path) -> dict:
    """The header of the ``.clw`` file ``path`` (``format`` "clw", shape, spacing, origin, levels, channels,
    interpolation, focus, content box, transfer function (as read: its ``opacity_unit`` 1 where a version 1 stored
    none), the input's ``value_range`` (None: a classified model's, or not recorded), the whole file's ``model_error``
    against its input (None: not recorded; :func:`~clwave.io.clw.record_error`), the input's ``noise_sigma`` per
    channel (:attr:`~clwave.WaveletVolume.noise_sigma`; None: not recorded), the value ``subtracted`` from
    the input's values and the
    ``obliquity`` of its axes to its scanner's: 0 where the file records none, its world ``unit``: None where it
    records none, whether it holds a ``photo``'s colour and alpha, not classified, the ``provenance``, the file and
    frame it was read from, and the ``modality`` of the source (:attr:`~clwave.Volume.modality`): None where it
    records none) with, per channel group, its wavelet, channels, the
    coefficients it keeps and their share of the voxels, and its quantisation step (None: float32
    values); and the file's size.  ``file``, ``format``, ``bytes``, ``shape``, ``channels``, ``spacing``, ``origin``,
    ``obliquity`` and ``unit`` are keys of a volume file's description too (:data:`~clwave.io.loaders.DESCRIBED`,
    ``clwave info``'s ``unit``).  The header
    is checked as a read checks it (:func:`~clwave.io.clw_header.checked_header`); a member that does not match it is
    refused (:class:`~clwave.errors.FileFormatError`, from :func:`~clwave.io.clw.open_clw`)."""
    path = Path(path)
    with open_clw(path) as (h5, header):
        shape, levels, channels, groups = checked_header(header)
        voxels = int(np.prod(shape))
        described = []
        for gi, g in enumerate(groups):
            positions, values = h5.get(f"g{gi}/positions"), h5.get(f"g{gi}/values")
            kept = member_rows(positions, 1)
            check_dataset(positions, (kept,), np.int64)
            step = checked_values(values, (kept, len(g["channels"])))
            described.append(dict(wavelet=_WAVELETS[g["wavelet"]], order=g["wavelet"], channels=g["channels"],
                                  kept=kept, share=kept / voxels, quantisation=step))
    facts = {name: header.get(name) for name in ("spacing", "origin", "interpolate", "focus", "content", "value_range",
                                                 "model_error", "noise_sigma")}
    tf = header.get("transfer_function")  # as read: a version 1's opacity unit 1 (TransferFunction.from_dict)
    facts["transfer_function"] = None if tf is None else TransferFunction.from_dict(tf).to_dict()
    return dict(file=str(path), format="clw", bytes=path.stat().st_size, shape=list(shape), levels=levels,
                channels=channels, **facts, subtracted=header.get("offset", 0.0),
                obliquity=header.get("obliquity", 0.0),
                unit=header.get("unit"), photo=header.get("photo", False),
                provenance=header.get("provenance"), modality=header.get("modality"),
                groups=described)
