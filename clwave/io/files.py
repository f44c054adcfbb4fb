"""Writing files without losing anything: refuse to overwrite, publish atomically, leave nothing behind.

A file is written as an unnamed file in the target folder (Linux ``O_TMPFILE``: a process killed
while writing, even by SIGKILL, leaves nothing) and published in one step: a hard link, which fails
when the name exists (so of two writers racing for one new name, one wins and the other is told),
or, with ``overwrite``, a link to a temporary name renamed over the old file.  Where unnamed files
are not available, the file is written under a temporary name, removed on every way out Python
sees (errors, Ctrl-C, SIGTERM through the command line).

A command's several outputs (an image, its raw values, its figures; a folder of frames) are written
first and published together at its end (:func:`published_together`): a failure or a signal before
then leaves none of them, and a failure while they are published restores what was there (a file
replaced with ``overwrite`` is kept under a hidden link until every output is published).  A folder is
written under a temporary name beside it and renamed into place, or its files moved into the empty
folder there (a process killed by SIGKILL leaves that hidden folder).
"""

from __future__ import annotations

import contextlib
import contextvars
import errno
import io
import os
import re
import shutil
import tempfile
from pathlib import Path

from ..errors import ClwaveError, InputError, OutputError, OutputExistsError

#: the outputs of the running :func:`published_together`, if any
_STAGING = contextvars.ContextVar("clwave_staging", default=None)


def check_suffix(path, suffixes) -> Path:
    """``path`` as a Path, or an InputError unless it ends in one of ``suffixes`` (".clw", ...)."""
    path = Path(path)
    if path.suffix.lower() not in suffixes:
        named = ", ".join(suffixes[:-1]) + " or " + suffixes[-1] if len(suffixes) > 1 else suffixes[0]
        raise InputError(f"cannot write {path}: use {named}")
    return path


def write_atomic(path, writer, overwrite=False) -> Path:
    """Call ``writer(binary_file)`` on a temporary file beside ``path``, then publish it there (within
    :func:`published_together`: when its caller publishes every output at once).

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
    staging, temporary = _STAGING.get(), None
    try:
        with _writing(path):
            temporary = _Temporary(path, overwrite)
            writer(temporary.file)
            temporary.file.flush()
            if staging is None or staging.holds(folder):  # a staged folder's files go straight into it
                temporary.publish()
        if staging is not None and not staging.holds(folder):
            staging.files[path], temporary = temporary, None
    finally:
        if temporary is not None:
            temporary.close()
    return path


@contextlib.contextmanager
def published_together():
    """A command's outputs published together, after every one is written: within the ``with``, :func:`write_atomic`
    writes each to a temporary beside it, and the yielded :class:`Staging`'s ``publish()`` gives them their names at
    once; leaving the ``with`` otherwise (an error, a signal) discards them all (coordinates.md §4)."""
    staging = Staging()
    token = _STAGING.set(staging)
    try:
        yield staging
    finally:
        _STAGING.reset(token)
        staging.discard()


class Staging:
    """The outputs of :func:`published_together` while they are written: files (by their target path) and folders."""

    def __init__(self):
        self.files, self.folders = {}, {}

    def size(self, path) -> int:
        """The size in bytes of the written, unpublished file ``path``."""
        return os.fstat(self.files[Path(path)].file.fileno()).st_size

    def readable(self, path) -> str:
        """A path to read the written, unpublished file ``path`` by: an unnamed file is given a hidden name for it
        (which a process killed by SIGKILL leaves behind: only where a re-read by name cannot be avoided)."""
        return self.files[Path(path)].readable

    def update(self, path, writer):
        """Call ``writer(binary_file)`` on the written, unpublished file ``path`` again: what is measured from it as
        written, added to it before it is published (``clwave compress``'s model error)."""
        with _writing(path):
            writer(self.files[Path(path)].file)

    def folder(self, path, force=False, replaces=None) -> Path:
        """A temporary folder beside the folder ``path`` to write its files into (:func:`write_atomic` publishes them
        there at once), published with the files: renamed to ``path`` where nothing is there, else its files moved
        into the folder there (``path`` may be a symbolic link to it), which must be empty: one that another writer
        filled meanwhile is refused; with ``force`` into a folder that is not empty, its files whose names match
        ``replaces`` (a regular expression) but are not among those moved in removed."""
        path = Path(path)
        with _writing(path):
            self.folders[path] = _Folder(path, force, replaces)
        return self.folders[path].tmp

    def holds(self, folder) -> bool:
        return any(Path(folder) == f.tmp for f in self.folders.values())

    def publish(self):
        """Publish every output (files first, then folders); if one fails, those published before it are undone: a
        new name removed, a file replaced with ``overwrite`` put back (files moved with ``force`` into a folder that
        was not empty stay)."""
        done = []
        try:
            for target, item in [*self.files.items(), *self.folders.items()]:
                with _writing(target):
                    item.publish(keep_old=True)
                done.append(item)
        except BaseException:
            for item in reversed(done):
                item.unpublish()
            raise
        for item in done:
            item.close()  # the replaced files' links go

    def discard(self):
        for item in [*self.files.values(), *self.folders.values()]:
            item.close()
        self.files, self.folders = {}, {}


@contextlib.contextmanager
def _writing(path):
    """Writing errors as one line naming ``path``: a name taken meanwhile, permissions, a full disk."""
    try:
        yield
    except FileExistsError:
        taken = f"{path} appeared while it was being written (another writer?)"
        raise OutputExistsError(f"{taken}; pass overwrite=True (--force) to replace it",
                                cli=f"{taken}; pass --force to replace it") from None
    except OSError as exc:
        if isinstance(exc, ClwaveError):
            raise
        raise _cannot_write(path, exc) from None


class _Temporary:
    """A file written beside ``path``, unnamed (or under a temporary name) until :meth:`publish`."""

    def __init__(self, path, overwrite):
        self.path, self.overwrite, self.old, self.replaces = path, overwrite, None, False
        fd, self.tmp = _open_unnamed(path.parent, path.suffix)
        self.file = os.fdopen(fd, "w+b")  # readable too: HDF5 reads back what it writes

    @property
    def readable(self) -> str:
        """A name to open the file by before it is published: an unnamed file is given a temporary one (HDF5 opens
        no /proc/self/fd path), removed by :meth:`close`."""
        if self.tmp is None:
            tmp = Path(self.path.parent, f".{self.path.stem}.{os.getpid()}.{self.file.fileno()}{self.path.suffix}")
            _link_unnamed(self.file.fileno(), tmp)
            self.tmp = tmp
        return str(self.tmp)

    def publish(self, keep_old=False):
        """Give the file its name; ``keep_old``: a file it replaces kept under a hidden link, for :meth:`unpublish`
        to put back (removed by :meth:`close`)."""
        self.replaces = self.overwrite and os.path.lexists(self.path)
        if keep_old and self.replaces:
            self.old = _linked_aside(self.path, f".{self.path.name}.{os.getpid()}.{self.file.fileno()}.old")
        if self.tmp is None:
            _publish_unnamed(self.file.fileno(), self.path.parent, self.path, self.overwrite)
        else:
            _publish(self.tmp, self.path, self.overwrite)

    def unpublish(self):
        """Undo :meth:`publish`: the file it replaced put back, or the name it took removed (a file replaced on a
        filesystem without hard links is gone: the new one stays)."""
        with contextlib.suppress(OSError):
            if self.old is not None:
                os.replace(self.old, self.path)
                self.old = None
            elif not self.replaces:
                os.unlink(self.path)

    def close(self):
        # a write that failed (a full disk) leaves its bytes in the buffer, which the close tries again and raises for
        # once more, over the one-line error: the descriptor is closed all the same, the file is dropped anyway
        with contextlib.suppress(OSError):
            self.file.close()
        for name in (self.tmp, self.old):
            if name is not None and os.path.lexists(name):
                os.unlink(name)
        self.old = None


class _Folder:
    """A folder of files written under a temporary name beside ``path`` (:meth:`Staging.folder`)."""

    def __init__(self, path, force, replaces):
        self.path, self.force, self.replaces, self.renamed, self.moved = path, force, replaces, None, []
        self.tmp = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp"))

    def publish(self, keep_old=False):
        """Rename the folder to its path where nothing is there; else move its files into the folder there (its
        owner, mode and ACL kept; ``path`` a symbolic link to it too), which must be empty without ``force``."""
        target = Path(os.path.realpath(self.path))
        if not os.path.lexists(target):
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(self.tmp, 0o777 & ~umask)  # mkdtemp makes 0700; give the folder the usual permissions
            try:
                os.rename(self.tmp, target)
            except OSError as exc:
                if exc.errno in (errno.ENOTEMPTY, errno.EEXIST):  # made and filled meanwhile: another writer's
                    raise FileExistsError(self.path) from None
                raise
            self.renamed = target
            return
        if not target.is_dir():
            raise NotADirectoryError(errno.ENOTDIR, os.strerror(errno.ENOTDIR))
        if not self.force and any(target.iterdir()):  # filled since the command checked it: another writer's
            raise FileExistsError(self.path)
        names = {f.name for f in self.tmp.iterdir()}
        for name in sorted(names):
            _publish(self.tmp / name, target / name, self.force)  # without force, a name taken meanwhile refused
            self.moved.append(target / name)
        for old in target.iterdir():  # an earlier run's files of the kind written: the folder holds these alone
            if self.replaces and re.fullmatch(self.replaces, old.name) and old.name not in names:
                old.unlink()

    def unpublish(self):
        if self.renamed is not None:
            os.rename(self.renamed, self.tmp)
        elif not self.force:
            for path in self.moved:
                with contextlib.suppress(OSError):
                    os.unlink(path)

    def close(self):
        shutil.rmtree(self.tmp, ignore_errors=True)


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
    """Give an unnamed file a name, which refuses an existing name; with ``overwrite``, a temporary name renamed over
    the old file."""
    target = path if not overwrite else Path(folder, f".{path.name}.{os.getpid()}.{fd}.tmp")
    _link_unnamed(fd, target)
    if overwrite:
        try:
            os.replace(target, path)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(target)
            raise


def _linked_aside(path, name) -> Path | None:
    """A hard link ``name`` beside ``path`` to the file (or symbolic link) there, to put it back by; None where
    there is none, or the filesystem has no hard links."""
    aside = path.parent / name
    try:
        os.link(path, aside, follow_symlinks=False)
    except FileNotFoundError:
        return None
    except OSError as exc:
        if exc.errno not in (errno.EPERM, errno.EOPNOTSUPP, errno.ENOSYS):
            raise
        return None
    return aside


def _link_unnamed(fd, target):
    """linkat(AT_SYMLINK_FOLLOW) of /proc/self/fd/N (os.link takes that path only with a dir fd)."""
    root = os.open("/", os.O_RDONLY)
    try:
        os.link(f"/proc/self/fd/{fd}", target, src_dir_fd=root, follow_symlinks=True)
    finally:
        os.close(root)


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
