"""Typed errors: each carries one line saying what is wrong and what to do.

The command line prints ``clwave: error: <message>`` and exits with code 2 for
any :class:`ClwaveError`; library users can catch the specific subclasses.
"""

from __future__ import annotations

import contextlib
import numbers
import os
import sys
import threading
import warnings
from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class CommandWords:
    """What one command calls the fixes a refusal names (``{narrow}``, ``{distance}``, ``{tracer}`` in a
    :class:`ClwaveError`'s ``cli``): a refusal raised deep in a renderer names them without knowing which
    command called it."""

    narrow: str  #: the options that narrow a perspective view's cone, e.g. "--fov or --size"
    distance: str  #: the option that moves the eye (the X-ray source) away, e.g. "--distance"
    tracer: str  #: the command that ray-traces the same X-ray, e.g. "clwave render --method raytrace --xray"


class ClwaveError(Exception):
    """Base class: a user-facing problem with a one-line, actionable message.

    A message that names an API argument (``series=``) can say it in the command line's words
    too (``cli``: ``--series``), which the command line prints instead. With ``worded``, ``cli``
    names fixes whose options differ between commands as fields of :class:`CommandWords`, which
    the running command fills in (without them: the API's message).
    """

    def __init__(self, message, *, cli=None, worded=False):
        super().__init__(one_line(message))
        self.cli, self.worded = one_line(cli), worded

    def cli_message(self, words: CommandWords | None = None) -> str:
        if self.worded:
            return self.cli.format_map(asdict(words)) if words else str(self)
        return self.cli or str(self)


def one_line(text):
    """``text`` with its line breaks (any that ``str.splitlines`` breaks at: a form feed or a file separator from a
    file's words too), and the spaces around them, made one space: a message that shows a value's ``repr`` (a 2-D
    NumPy array's spans lines) stays one line; anything but a string as given."""
    return " ".join(text.split()) if isinstance(text, str) and text.splitlines() != [text] else text


class ClwaveWarning(UserWarning):
    """A result that is not what was asked for, said in one line, in the command line's words too (``cli``), which
    the command line prints as ``clwave: warning: ...``."""

    #: what the command line says once a run (None: each line once)
    once = None

    def __init__(self, message, *, cli=None):
        super().__init__(one_line(message))
        self.cli = one_line(cli or message)


class NearlyOpaqueWarning(ClwaveWarning):
    """A transfer function that makes a volume or model nearly opaque (docs/model.md §5): said once a command, whether
    its volume was checked (``classify``, ``check_visible``) or its model rendered (``transfer_function=``)."""

    once = "nearly opaque"


class NoisyModelWarning(ClwaveWarning):
    """A ``keep=`` or ``threshold=`` model of a noisy volume that keeps mostly noise (docs/model.md §2): said even where
    the command line's default ``--keep`` silences its budget warnings."""


#: this thread's list of the warnings :func:`caught_warnings` takes (an attribute ``sink``; none: not catching)
_catching = threading.local()


@contextlib.contextmanager
def caught_warnings():
    """clwave's warnings (:func:`warn_outside`) given on this thread meanwhile, into the list it yields instead of to
    :mod:`warnings`, whose filters and ``catch_warnings`` are the whole process's (not thread-safe: a viewer's render
    thread beside its build thread and the user's own code, docs/viewer.md §2).  Others' warnings (NumPy's) go on to
    :mod:`warnings`."""
    outer = getattr(_catching, "sink", None)
    _catching.sink = sink = []
    try:
        yield sink
    finally:
        _catching.sink = outer


def warn_outside(warning) -> None:
    """Warn with ``warning`` (a :class:`ClwaveWarning`, or any warning or message) attributed to the first caller
    outside the clwave package: the user's line, however deep inside clwave the warning is given (a fixed
    ``stacklevel`` points inside clwave where the call comes through another of its functions).  What Python 3.12's
    ``skip_file_prefixes`` does, by hand for 3.11.  Within :func:`caught_warnings` on this thread: into its list."""
    sink = getattr(_catching, "sink", None)
    if sink is not None:
        sink.append(warning if isinstance(warning, Warning) else UserWarning(warning))
        return
    package = os.path.dirname(__file__) + os.sep  # the form every module of the package has as co_filename
    frame, level = sys._getframe(1), 2  # level 2: warn_outside's caller
    while frame is not None and frame.f_code.co_filename.startswith(package):
        frame, level = frame.f_back, level + 1
    warnings.warn(warning, stacklevel=level)


class InputError(ClwaveError, ValueError):
    """A bad argument or a bad volume (NaN voxels, wrong shape, bad levels...)."""


class NothingVisibleError(InputError):
    """A transfer function that gives no voxel of a volume any opacity: every image of it would be blank."""


class FileFormatError(ClwaveError):
    """A file that cannot be read: unknown extension, truncated or corrupt."""


class OutputExistsError(ClwaveError, FileExistsError):
    """Refusing to overwrite an existing file without ``force``/``overwrite``."""


class OutputError(ClwaveError, OSError):
    """An output that cannot be written: permissions, a read-only or full filesystem."""


class WorkerLostError(ClwaveError, RuntimeError):
    """Chunked or cluster work that cannot finish: the Dask workers died running one of its tasks (docs/chunked.md
    §5)."""


class DeviceNotFoundError(ClwaveError):
    """No OpenCL platform, or no device matching the ``device`` request."""


class KernelBuildError(ClwaveError):
    """An OpenCL program failed to build; ``log`` holds the full build log."""

    def __init__(self, message, log=""):
        super().__init__(message)
        self.log = log


class DeviceMemoryError(ClwaveError, MemoryError):
    """The device has too little memory for the requested work."""


def finite_number(value, name) -> float:
    """``float(value)``, or an :class:`InputError` naming ``name`` when it is not one finite number (NumPy's scalars
    and 0-d arrays are numbers; a bool is not, though ``float(True)`` is 1)."""
    if isinstance(value, (str, bytes)):  # float("30") would pass: the API takes numbers
        raise InputError(f"{name} must be a number, got the string {value!r}")
    if isinstance(value, (bool, np.bool_)) or np.ndim(value) != 0:
        raise InputError(f"{name} must be one number, got {value!r}")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, got {value!r}") from None
    if number != number or number in (float("inf"), float("-inf")):
        raise InputError(f"{name}={number} must be finite")
    return number


def float32_number(value, name) -> float:
    """:func:`finite_number`, and within float32's range, in which clwave computes a volume's values (a value of
    1e308 subtracted made every voxel infinite); ``name`` is the command line's option too (``--name``)."""
    number, top = finite_number(value, name), float(np.finfo(np.float32).max)
    if abs(number) > top:
        why = f"must be within float32's range (+-{top:.3g}), in which clwave computes the values"
        raise InputError(f"{name}={number:g} {why}", cli=f"--{name} {number:g} {why}")
    return number


def reals(value, name, count, what, one=False) -> np.ndarray:
    """``value`` as ``count`` floats (``one``: a single number stands for all ``count``), or an :class:`InputError`
    "``name`` must be ``what``" when it is anything else: strings and bools included, which ``numpy.asarray(value,
    float)`` takes as numbers ("0.5", True as 1)."""
    items = np.asarray(value, dtype=object)
    shape_ok = (one and items.size == 1) or items.shape == (count,)  # one number: 0.5, [0.5] or [[0.5]]
    if not shape_ok or not all(isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_))
                               for x in items.ravel()):
        raise InputError(f"{name}={value!r} must be {what}")
    return np.broadcast_to(items.astype(float).ravel(), (count,)).copy()


def flag(value, name) -> bool:
    """``value`` as a bool, or an :class:`InputError` naming ``name`` when it is not True or False (``bool("False")``
    is True: a string, a number or None given for a switch would have turned it on or off silently)."""
    if not isinstance(value, (bool, np.bool_)):
        raise InputError(f"{name}={value!r} must be True or False")
    return bool(value)


def file_name(path) -> str:
    """``path`` as ``os.fspath`` gives it (a str or bytes), or InputError where it is no file or folder name."""
    if not isinstance(path, (str, os.PathLike)):
        raise InputError(f"path must be a file or folder name (str or pathlib.Path), got {type(path).__name__}")
    return os.fspath(path)


def type_name(value) -> str:
    """The full name of ``value``'s type, as a message names it: ``numpy.ndarray``, ``dask.array.core.Array``,
    ``clwave.Volume`` (clwave's by the name it exports), ``list`` (a builtin's bare)."""
    kind, module = type(value), type(value).__module__
    if module.startswith("clwave.") and getattr(sys.modules.get("clwave"), kind.__name__, None) is kind:
        module = "clwave"
    return kind.__qualname__ if module == "builtins" else f"{module}.{kind.__qualname__}"


def whole_number(value) -> bool:
    """Whether ``value`` is a whole number: an int, or a finite real without a fraction (not a bool or a string)."""
    if isinstance(value, (bool, np.bool_, str, bytes)):
        return False
    try:
        return float(value).is_integer()
    except (TypeError, ValueError, OverflowError):
        return False
