"""Transfer functions given otherwise than as a :class:`TransferFunction` (docs/model.md §5): named by the command line
(``--tf``) and every argument that takes one (``transfer_function=``, ``tf=``, :func:`as_transfer_function`), a preset
or a file of points, or given as a matplotlib colormap.

* ``.json``: what :meth:`TransferFunction.to_dict` writes (``points``, maybe ``window``, ``name`` and
  ``opacity_unit``), a bare list of ``(value, r, g, b, opacity)`` rows, or ``{"labels": {"1": [r, g, b, opacity],
  ...}}`` (a categorical function, :meth:`TransferFunction.labels`);
* ``.csv``: rows ``value, r, g, b, opacity``; ``#`` lines are comments, a first row of words a header; a header
  whose first column is ``label`` makes the rows ``label, r, g, b, opacity``, a categorical function.
"""

from __future__ import annotations

import csv
import io
import json
import reprlib
from os import PathLike
from pathlib import Path

from ..errors import InputError, type_name
from .tf_presets import is_colormap
from .transfer import TransferFunction

#: Suffixes read as files of points (anything else names a preset).
SUFFIXES = (".json", ".csv")
#: A transfer function's file is small (a few points a line): larger ones are refused before they are read.
MAX_BYTES = 1 << 20


def as_transfer_function(tf, argument="transfer_function") -> TransferFunction | None:
    """``tf`` as a TransferFunction (None as None), however an ``argument`` gives it: a TransferFunction, a preset name
    or a ``.json``/``.csv`` file (:func:`named_transfer_function`), a matplotlib ``Colormap``
    (:meth:`TransferFunction.from_colormap`) or the dict of :meth:`TransferFunction.to_dict`; anything else an
    InputError naming the constructors."""
    if tf is None or isinstance(tf, TransferFunction):
        return tf
    if isinstance(tf, (str, PathLike)):
        return named_transfer_function(tf)
    if is_colormap(tf):
        return TransferFunction.from_colormap(tf)
    if isinstance(tf, dict) and "points" in tf:
        return TransferFunction.from_dict(tf)
    presets = ", ".join(TransferFunction.PRESETS)
    got = "a dict without 'points'" if isinstance(tf, dict) else type_name(tf)
    raise InputError(f"{argument}= takes a clwave.TransferFunction, a preset name ({presets}), a .json or .csv file, "
                     f"a matplotlib colormap or the dict of TransferFunction.to_dict(), got {got}: make one with "
                     f"TransferFunction([(value, r, g, b, opacity), ...]), .preset(name), .labels({{label: (r, g, b, "
                     f"opacity)}}) or .from_colormap(cmap)")


def stored_transfer_function(tf) -> dict | None:
    """``tf`` (as :func:`as_transfer_function` takes it, or None) as a model stores it, :meth:`TransferFunction.to_dict`
    (a dict given checked as a file's reader checks it, io/clw_header.py, so that every model saved can be read)."""
    tf = as_transfer_function(tf)
    return None if tf is None else tf.to_dict()


def named_transfer_function(text, window=None) -> TransferFunction:
    """The preset named ``text``, or the file it names (a :data:`SUFFIXES` name); ``window`` (None: the preset's or
    the file's own) as :meth:`TransferFunction.preset` takes it."""
    if not str(text).lower().endswith(SUFFIXES):
        return TransferFunction.preset(text, window=window)
    tf = read_transfer_function(text)
    return tf if window is None else tf.under(window)


def read_transfer_function(path) -> TransferFunction:
    """The transfer function in a ``.json`` or ``.csv`` file (module docstring); a file that is not one is refused
    in one line naming it and what is wrong."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"transfer function file {path} does not exist (or is not a file); give a .json or .csv "
                         f"file of (value, r, g, b, opacity) rows, or a preset: {', '.join(TransferFunction.PRESETS)}")
    if path.stat().st_size > MAX_BYTES:
        raise InputError(f"transfer function file {path} has {path.stat().st_size:,} bytes, more than a function of "
                         f"points takes ({MAX_BYTES:,} at most)")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read transfer function file {path}: {exc}") from None
    try:
        return _from_json(path, text) if path.suffix.lower() == ".json" else _from_csv(path, text)
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from None


def _from_json(path, text) -> TransferFunction:
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise InputError(f"not JSON ({exc})") from None
    except RecursionError:  # Python's parser recurses once a level
        raise InputError("its JSON is nested deeper than Python's parser reaches; a function of points is 3 deep")
    if isinstance(data, dict) and set(data) == {"labels"}:
        return TransferFunction.labels(data["labels"], name=path.stem)
    if isinstance(data, list):
        return TransferFunction(data, name=path.stem)
    if isinstance(data, dict) and "points" in data:
        return TransferFunction.from_dict(dict(data, name=data.get("name", path.stem)))
    raise InputError('give a list of (value, r, g, b, opacity) rows, {"points": rows, "window": [lo, hi]} (as '
                     'TransferFunction.to_dict writes) or {"labels": {"1": [r, g, b, opacity], ...}}')


def _from_csv(path, text) -> TransferFunction:
    try:
        rows = [row for row in csv.reader(io.StringIO(text)) if row and not row[0].lstrip().startswith("#")]
    except csv.Error as exc:  # e.g. a field past the csv module's limit (131,072 characters)
        raise InputError(f"not CSV ({exc})") from None
    header = rows and not _numbers(rows[0])
    labels = header and rows[0][0].strip().lower() == "label"
    body = rows[1:] if header else rows
    values = []
    for n, row in enumerate(body, 2 if header else 1):
        if len(row) != 5 or not _numbers(row):
            raise InputError(f"row {n} {reprlib.repr(','.join(row))} is not 5 numbers "
                             f"({'label' if labels else 'value'}, r, g, b, opacity)")
        values.append([float(v) for v in row])
    if labels:
        return TransferFunction.labels({row[0]: row[1:] for row in values}, name=path.stem)
    return TransferFunction(values, name=path.stem)


def _numbers(row) -> bool:
    try:
        [float(v) for v in row]
    except ValueError:
        return False
    return True
