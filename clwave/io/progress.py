"""Progress of long steps (docs/coordinates.md §4): whether it shows, decided here alone (:func:`showing`), and its
tqdm bar: text on a terminal, a widget in Jupyter (text where ipywidgets is missing), nothing in a pipe or a log
unless asked."""

from __future__ import annotations

import contextlib
import importlib.util
import sys
import threading

from ..errors import flag

_setting = {"show": None}  # show_progress's: None decides by where the bar would go


class show_progress:
    """Whether clwave's long steps show their progress, process-wide: True always (a log's text bar too), False never,
    None (the default) on a terminal or in Jupyter only.  Set for the rest of the session as a call,
    ``clwave.show_progress(False)``, or for a block as a context manager that puts back the setting it replaced,
    ``with clwave.show_progress(False): ...``; a call's own ``progress_bar=`` (``load``, ``from_volume``) comes
    first."""

    def __init__(self, show=None):
        show = None if show is None else flag(show, "show_progress")
        self.previous, _setting["show"] = _setting["show"], show

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        _setting["show"] = self.previous


def in_notebook() -> bool:
    """Whether this is a Jupyter kernel (IPython's shell has a kernel), as Dask's ``distributed.progress`` tells."""
    ipython = sys.modules.get("IPython")
    shell = ipython.get_ipython() if ipython is not None else None
    return getattr(shell, "kernel", None) is not None


def showing(enabled=None) -> bool:
    """Whether a bar shows: ``enabled`` where given (a call's ``progress_bar=``), else :class:`show_progress`'s
    setting, else where stderr is a terminal or this is a Jupyter kernel (whose stderr is no terminal)."""
    if enabled is None:
        enabled = _setting["show"]
    if enabled is None:
        return sys.stderr.isatty() or in_notebook()
    return bool(enabled)


def progress(iterable=None, *, total=None, desc=None, enabled=None, bar_format=None):
    """``iterable`` (or a bar to ``update``) in a tqdm bar where :func:`showing` says so, gone when done."""
    shown = showing(enabled)
    if shown and in_notebook() and importlib.util.find_spec("ipywidgets") is not None:
        from tqdm.auto import tqdm  # a widget (text in a Qt console or Spyder, as tqdm tells them)
    else:  # imported here: tqdm.auto's import in a kernel without ipywidgets warns
        from tqdm.std import tqdm
    return tqdm(iterable, total=total, desc=desc, disable=not shown, leave=False, file=sys.stderr,
                dynamic_ncols=True, bar_format=bar_format)


@contextlib.contextmanager
def status(desc, after=1.0, enabled=None):
    """A one-line status ``desc`` over a block that is usually quick (a cached kernel build), shown where
    :func:`showing` says so once the block has lasted ``after`` seconds, gone when it ends.  Yields the timer that
    shows it (``None`` where nothing would show: no thread then)."""
    if not showing(enabled):
        yield None
        return
    lock, shown = threading.Lock(), {"done": False, "bar": None}

    def show():
        with lock:
            if not shown["done"]:
                shown["bar"] = progress(desc=desc, enabled=True, bar_format="{desc}")

    timer = threading.Timer(after, show)
    timer.daemon = True
    timer.start()
    try:
        yield timer
    finally:
        timer.cancel()
        with lock:
            shown["done"] = True
            if shown["bar"] is not None:
                shown["bar"].close()


def dask_progress(enabled=None):
    """Dask's own bar (``dask.diagnostics.ProgressBar``, on stderr) over a computation on Dask's local schedulers,
    where :func:`showing` says so; work on a ``distributed`` client is counted by :func:`clwave.schedulers.stream`."""
    if not showing(enabled):
        return contextlib.nullcontext()
    from dask.diagnostics import ProgressBar

    return ProgressBar(out=sys.stderr)
