"""Progress bars for long steps: a tqdm bar on a terminal, nothing otherwise."""

from __future__ import annotations

import sys

from tqdm.auto import tqdm


def progress(iterable=None, *, total=None, desc=None, enabled=None):
    """Wrap ``iterable`` in a tqdm bar shown only when stderr is a terminal.

    ``enabled`` forces the bar on (True) or off (False); None decides by the terminal.
    """
    if enabled is None:
        enabled = sys.stderr.isatty()
    return tqdm(iterable, total=total, desc=desc, disable=not enabled, leave=False,
                file=sys.stderr, dynamic_ncols=True)
