"""Writing files without losing anything: refuse to overwrite, publish atomically, leave nothing behind.

A file is written as an unnamed file in the target folder (Linux ``O_TMPFILE``: a process killed
while writing, even by SIGKILL, leaves nothing) and published in one step: a hard link, which fails
when the name exists (so of two writers racing for one new name, one wins and the other is told),
or, with ``overwrite``, a link to a temporary name renamed over the old file.  Where unnamed files
are not available, the file is written under a temporary name, removed on every way out Python
sees (errors, Ctrl-C, SIGTERM through the command line).
"""

from __future__ import annotations

import contextlib
import errno
import io
import os
import tempfile
from pathlib import Path

from ..errors import InputError, OutputError, OutputExistsError


def check_suffix(path, suffixes) -> Path:
    """``path`` as a Path, or an InputError unless it ends in one of ``suffixes`` (".clw", ...)."""
    path = Path(path)
    if path.suffix.lower() not in suffixes:
        named = ", ".join(suffixes[:-1]) + " or " + suffixes[-1] if len(suffixes) > 1 else suffixes[0]
        raise InputError(f"cannot write {path}: use {named}")
    return path


def write_atomic(path, writer, overwrite=False) -> Path:
    """Call ``writer(binary_file)`` on a temporary file beside ``path``, then publish it there.

    An existing ``path`` is only replaced with ``overwrite``; a failed or interrupted write leaves
    nothing behind.  Permission and disk errors are an :class:`OutputError`.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise OutputExistsError(f"{path} exists; pass overwrite=True (--force) to replace it")
    folder = path.parent
    if not folder.is_dir():
        raise InputError(f"the folder of {path} does not exist; create it first")
    if path.is_dir():
        raise InputError(f"{path} is a folder; name a file")
    tmp = None
    try:
        fd, tmp = _open_unnamed(folder, path.suffix)
        with os.fdopen(fd, "w+b") as fh:  # readable too: HDF5 reads back what it writes
            writer(fh)
            fh.flush()
            if tmp is None:
                _publish_unnamed(fh.fileno(), folder, path, overwrite)
        if tmp is not None:
            _publish(tmp, path, overwrite)
    except FileExistsError:
        raise OutputExistsError(f"{path} appeared while it was being written (another writer?); pass "
                                f"overwrite=True (--force) to replace it") from None
    except OSError as exc:
        raise _cannot_write(path, exc) from None
    finally:
        if tmp is not None and os.path.exists(tmp):
            os.unlink(tmp)
    return path


def check_writable(path):
    """Refuse (:class:`OutputError`) a ``path`` whose folder takes no new file (no permission, a read-only or
    special filesystem such as /proc), found by opening a file there as :func:`write_atomic` does and removing it:
    before any work, not after it."""
    path = Path(path)
    try:
        fd, tmp = _open_unnamed(path.parent, path.suffix)
        os.close(fd)
        if tmp is not None:
            os.unlink(tmp)
    except OSError as exc:
        raise _cannot_write(path, exc) from None


def _cannot_write(path, exc: OSError) -> OutputError:
    return OutputError(f"cannot write {path}: {exc.strerror or exc}; check the folder's permissions and free space")


def _open_unnamed(folder, suffix) -> tuple:
    """``(fd, None)`` of an unnamed file in ``folder``, or ``(fd, name)`` of a temporary file where the
    system has no unnamed files (or no /proc to link them from)."""
    try:
        fd = os.open(folder, os.O_TMPFILE | os.O_RDWR, 0o666)  # the umask applies, as to any new file
        if os.path.exists(f"/proc/self/fd/{fd}"):
            return fd, None
        os.close(fd)
    except (AttributeError, OSError):  # not Linux, or a filesystem without O_TMPFILE
        pass
    fd, tmp = tempfile.mkstemp(dir=folder, suffix=suffix + ".tmp")
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the file the usual permissions
    return fd, tmp


def _publish_unnamed(fd, folder, path, overwrite):
    """Give an unnamed file a name: linkat(AT_SYMLINK_FOLLOW) of /proc/self/fd/N (os.link takes that path
    only with a dir fd), which refuses an existing name; with ``overwrite``, a temporary name renamed over
    the old file."""
    root = os.open("/", os.O_RDONLY)
    try:
        target = path if not overwrite else Path(folder, f".{path.name}.{os.getpid()}.{fd}.tmp")
        os.link(f"/proc/self/fd/{fd}", target, src_dir_fd=root, follow_symlinks=True)
    finally:
        os.close(root)
    if overwrite:
        os.replace(target, path)


def _publish(tmp, path, overwrite):
    """Give the written file its name: a link that refuses an existing name, or a rename over it."""
    if overwrite:
        os.replace(tmp, path)
        return
    try:
        os.link(tmp, path)
    except OSError as exc:
        if exc.errno not in (errno.EPERM, errno.EOPNOTSUPP, errno.ENOSYS):
            raise
        if path.exists():  # a filesystem without hard links: check, then rename
            raise FileExistsError(path) from None
        os.replace(tmp, path)


@contextlib.contextmanager
def hdf5_target(fh):
    """The file object to give h5py for writing HDF5 into ``fh`` (a file of :func:`write_atomic`); the
    first error writing it is raised after the HDF5 file, closed inside the ``with``, is closed."""
    target = HDF5Sink(fh)
    yield target
    target.check()


class HDF5Sink:
    """A file object for h5py writing into ``fh`` (:func:`hdf5_target`) that never fails HDF5.

    An exception raised in h5py's file-object driver stays set in Python, so that every later call of the
    driver fails too: HDF5 cannot close the file and keeps it open until the interpreter's exit flushes it
    through a closed file object (SIGSEGV).  So after the first failure (a full disk), writes are dropped,
    and :meth:`check` raises it, between HDF5 calls.  Unbuffered, so that only a write can fail, and
    writing on through a partial write.
    """

    def __init__(self, fh):
        fh.flush()
        self.raw, self.error = io.FileIO(fh.fileno(), "r+b", closefd=False), None

    def seek(self, offset, whence=os.SEEK_SET):
        return self.raw.seek(offset, whence)

    def tell(self):
        return self.raw.tell()

    def read(self, size=-1):
        return self.raw.read(size)

    def readinto(self, buffer):
        return self.raw.readinto(buffer)

    def write(self, data):
        view, done = memoryview(data).cast("B"), 0
        while done < len(view) and self.error is None:
            done += self._quietly(self.raw.write, view[done:]) or 0
        return len(view)

    def truncate(self, size=None):
        return self._quietly(self.raw.truncate, size)

    def flush(self):
        pass  # unbuffered

    def check(self):
        """Raise the first error of a write, if any."""
        if self.error is not None:
            raise self.error

    def _quietly(self, operation, argument):
        if self.error is None:
            try:
                return operation(argument)
            except OSError as exc:
                self.error = exc
        return None
