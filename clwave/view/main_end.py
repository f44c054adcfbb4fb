"""Viewers a script leaves open, closed at the interpreter's exit before it joins the render and build threads
(docs/viewer.md §1).

The exit (``threading._shutdown``) calls threading's own exit hooks, last registered first, of which
``concurrent.futures`` registers the one that joins every thread pool's threads, so waiting for the render under
way; it then marks the main thread ended, joins the other non-daemon threads, and only then runs the ``atexit``
hooks.  No public hook runs before that join (an ``atexit`` hook or a ``weakref.finalize`` runs after it, a thread
joining the main thread wakes after it, and a pool's threads are joined whichever thread made them), so the close is
registered with ``threading._register_atexit``, private (there since Python 3.9), after ``concurrent.futures``
registered its join: it runs first, and the viewers' stop ends the render at its next band (``threads.stop_on``).
"""

from __future__ import annotations

import atexit
import concurrent.futures.thread  # noqa: F401  (its join registered before the close below, which then runs first)
import logging
import threading
import weakref

_open = weakref.WeakSet()  # the BackgroundServers not closed yet (a closed one's thread lets it go)
_lock = threading.Lock()
_registered = False


def close_at_exit(server) -> None:
    """Close ``server`` (a :class:`~clwave.view.background.BackgroundServer`) at the interpreter's exit if it is open
    then, before the exit joins its render and build threads."""
    global _registered
    with _lock:
        _open.add(server)
        if not _registered:  # without threading's hook (a later Python): atexit's, after the join
            getattr(threading, "_register_atexit", atexit.register)(close_all)
            _registered = True


def closed(server) -> None:
    """Forget ``server``, closed by its viewer."""
    with _lock:
        _open.discard(server)


def close_all() -> int:
    """Close each open viewer (:meth:`clwave.Viewer.close_all`, and at the exit), returning how many were open; one
    that fails to close is logged and the others closed: an exception here would end ``threading._shutdown``, which
    catches none, before its join of the thread pools."""
    with _lock:
        servers = list(_open)
    for server in servers:
        try:
            server.close()
        except Exception:
            logging.getLogger(__name__).exception("clwave: closing the viewer %r failed", server)
        closed(server)
    return len(servers)
