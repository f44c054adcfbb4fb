"""The ``clwave`` command line (never interactive): one module per command.

Every user mistake ends with one line ``clwave: error: ...`` on stderr and exit
code 2; an existing output file is never replaced without ``--force``.
"""

from __future__ import annotations

import argparse
import contextlib
import re
import signal
import sys
import threading
import warnings
from functools import partial

from ..device.memory import out_of_threads
from ..errors import ClwaveError, ClwaveWarning, InputError, OutputError
from ..io.progress import show_progress
from . import compress, drr, info, progressive, render, view
from .checks import check_options
from .options import silence_stdout, warn

EXIT_USAGE = 2
#: what to ask for instead when a command runs out of memory (the rendering commands: fewer pixels)
MEMORY_FIXES = {"compress": "keep fewer coefficients (--keep), read the volume chunk by chunk (--chunks auto) or "
                            "crop it"}
EXIT_PIPE = 128 + signal.SIGPIPE  # stdout's reader left (`| head`): as a program the signal ended, with no message


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (its default prints the whole usage first), taking a value that starts with a
    negative number as a value: ``--tf-window -200,300`` as ``--tf-window=-200,300``."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        # Python 3.11's argparse takes "-200" for a number but "-200,300" for an option; 3.13 matches the start
        # alone, as here (no clwave option starts with "-" and a digit)
        self._negative_number_matcher = re.compile(r"^-\.?\d")

    def error(self, message):
        raise InputError(f"{message} (see `{self.prog} --help`)")


#: the subcommands, in the order ``clwave --help`` lists them
COMMANDS = (info, compress, render, progressive, drr, view)


def make_parser():
    parser = _Parser(prog="clwave", description="Wavelet-domain volume rendering (OpenCL).")
    parser.add_argument("--version", action="version", version=_version())
    parser.add_argument("--debug", action="store_true", help="show the traceback of an internal error")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for command in COMMANDS:
        command.add_parser(sub)
    return parser


def _version():
    from .. import __version__
    return f"clwave {__version__}"


class Terminated(BaseException):
    """SIGTERM, raised where the program is, so that what it was writing is cleaned up on the way out.  A
    BaseException, as KeyboardInterrupt is: a reader's ``except Exception`` (``loaders.shared.reading``) took it for a
    corrupt file (exit 2, not 143)."""


def _terminate(signum, frame):
    raise Terminated()


def main(argv=None) -> int:
    """Run the command line ``argv`` (default ``sys.argv[1:]``); its exit code.  Threads may each run one at once
    (:func:`_running`)."""
    with _running():
        return _main(argv)


_lock = threading.Lock()
_runs = {"count": 0, "stdout": None, "warnings": None}  # the runs of main under way, and what they found


@contextlib.contextmanager
def _running():
    """While a run of :func:`main` is under way in any thread: ``sys.stdout`` a :class:`_CheckedStdout` (none where
    stdout is closed: ``>&-`` leaves ``sys.stdout`` None, which ``print`` ignores) and clwave's warnings one line
    each, once a run; both put back when the last run ends, so that runs that overlap in threads leave neither
    swapped (a swap a run undid itself left the other's in place)."""
    with _lock:
        if _runs["count"] == 0:
            _runs["stdout"], _runs["warnings"] = sys.stdout, warnings.catch_warnings()
            _runs["warnings"].__enter__()
            warnings.simplefilter("always", ClwaveWarning)
            warnings.showwarning = partial(_show_warning, shown=warnings.showwarning, said=set())
            if sys.stdout is not None:
                sys.stdout = _CheckedStdout(sys.stdout)
        _runs["count"] += 1
    try:
        yield
    finally:
        with _lock:
            _runs["count"] -= 1
            if _runs["count"] == 0:
                sys.stdout = _runs["stdout"]
                _runs["warnings"].__exit__(None, None, None)


def _main(argv) -> int:
    previous = signal.signal(signal.SIGTERM, _terminate) if threading.current_thread() is threading.main_thread() \
        else None
    debug = "--debug" in (sys.argv[1:] if argv is None else argv)
    args = None
    try:
        args = make_parser().parse_args(argv)
        check_options(args)  # before the input is opened: a mistake costs no read
        given = getattr(args, "progress", None)  # the input commands' --progress/--no-progress
        with contextlib.nullcontext() if given is None else show_progress(given):
            return args.run(args)
    except ClwaveError as exc:  # in the running command's own options (its ``words``, errors.CommandWords)
        print(f"clwave: error: {exc.cli_message(getattr(args, 'words', None))}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("clwave: interrupted", file=sys.stderr)
        return 130
    except Terminated:
        print("clwave: terminated", file=sys.stderr)
        return 143
    except MemoryError as exc:
        return _out_of_memory(args, f"not enough memory for this work ({str(exc) or 'an allocation failed'})")
    except Exception as exc:  # a bug: one line, the traceback only when asked for
        if out_of_threads(exc):
            return _out_of_memory(args, f"not enough memory or threads for this work ({exc}; a memory limit, ulimit "
                                        f"-v, leaves no room for a thread's stack)")
        if isinstance(exc, BrokenPipeError) and _reader_gone():
            return EXIT_PIPE
        if debug:
            raise
        print(f"clwave: internal error ({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}); "
              f"this is a bug in clwave: please report it with the command line, and run with --debug for the "
              f"traceback", file=sys.stderr)
        return 1
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


class _CheckedStdout:
    """``sys.stdout`` while a command runs: a write it cannot make (``>/dev/full``, a full disk) is one line naming
    stdout (exit 2; a warning after the outputs are published: options.finish), stdout then pointed at /dev/null so
    that the interpreter's last flush fails no more (its exit code would be 120); a pipe whose reader left stays a
    BrokenPipeError (exit 141, as a program the signal ended)."""

    def __init__(self, stream):
        self.stream = stream

    def write(self, text):
        return self._checked(self.stream.write, text)

    def flush(self):
        return self._checked(self.stream.flush)

    def __getattr__(self, name):
        return getattr(self.stream, name)

    def _checked(self, operation, *args):
        try:
            return operation(*args)
        except BrokenPipeError:
            raise
        except OSError as exc:
            silence_stdout()
            raise OutputError(f"cannot write to standard output: {exc.strerror or exc}; point stdout at a file or a "
                              f"pipe that takes it") from None


def _out_of_memory(args, what) -> int:
    fix = MEMORY_FIXES.get(getattr(args, "command", None), "render fewer pixels, keep fewer coefficients or use a "
                                                          "smaller volume")
    print(f"clwave: error: {what}; {fix}", file=sys.stderr)
    return EXIT_USAGE


def _show_warning(message, category, filename, lineno, file=None, line=None, *, shown, said):
    """clwave's warnings (:class:`ClwaveWarning`) as one line in the command line's words, each line once (``said``:
    those printed, e.g. an oblique volume's, which every pose's view gives), or each kind once where it says so (its
    ``once``); others as Python shows them."""
    if isinstance(message, ClwaveWarning):
        key = message.once or message.cli
        if key not in said:
            said.add(key)
            warn(message.cli)
    else:
        shown(message, category, filename, lineno, file, line)


def _reader_gone() -> bool:
    """Whether stdout is a pipe its reader has closed (poll tells so with POLLERR on Linux), pointing stdout at
    /dev/null if so, so that the interpreter's last flush says nothing either (Python docs, "Note on SIGPIPE"); a
    broken pipe elsewhere (a socket) is no such end."""
    import select

    try:
        fd = sys.stdout.fileno()
        poll = select.poll()
        poll.register(fd, select.POLLOUT)
        if not any(events & select.POLLERR for _, events in poll.poll(0)):
            return False
    except (OSError, ValueError):  # a stdout with no file descriptor (a test's capture)
        return False
    silence_stdout()
    return True


if __name__ == "__main__":
    sys.exit(main())
