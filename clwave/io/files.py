"""Writing files without losing anything: refuse to overwrite, write atomically."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from ..errors import InputError, OutputExistsError


def write_atomic(path, writer, overwrite=False) -> Path:
    """Call ``writer(binary_file)`` on a temporary file in the same folder, then move it into place.

    An existing ``path`` is only replaced with ``overwrite``; a failed write leaves nothing behind.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise OutputExistsError(f"{path} exists; pass overwrite=True (--force) to replace it")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise InputError(f"the folder of {path} does not exist; create it first")
    fd, tmp = tempfile.mkstemp(dir=folder, suffix=path.suffix + ".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            writer(fh)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the file the usual permissions
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path
