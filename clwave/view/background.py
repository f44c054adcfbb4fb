"""A viewer's server on an event loop of its own thread (docs/viewer.md §1): what ``clwave.view()`` runs for scripts
and notebooks, closed by :meth:`Viewer.close` or at the interpreter's exit (:mod:`clwave.view.main_end`)."""

from __future__ import annotations

import asyncio
import logging
import threading

log = logging.getLogger("clwave.view")


class BackgroundServer:
    """A :class:`~clwave.view.server.ViewServer` on an event loop of its own thread (for scripts and notebooks)."""

    def __init__(self, server):
        self.server = server
        self.loop = asyncio.new_event_loop()
        started = threading.Event()
        self.thread = threading.Thread(target=self._run, args=(started,), name="clwave-view-server", daemon=True)
        self.thread.start()
        started.wait()
        if self._error is not None:
            raise self._error

    def _run(self, started):
        asyncio.set_event_loop(self.loop)
        self._error = None
        try:
            self.loop.run_until_complete(self.server.start())
        except Exception as exc:  # any failure to start reaches the caller, which waits on `started`
            self._error = exc
            self.loop.run_until_complete(self.server.stop())
            self.loop.close()
            return
        finally:
            started.set()
        self.loop.run_forever()

    def close(self):
        if self.thread.is_alive():
            # no time limit: the stop waits for the reading step under way (bounded, docs/viewer.md §1)
            try:
                asyncio.run_coroutine_threadsafe(self.server.stop(), self.loop).result()
            except Exception:  # noqa: BLE001  (a bug in the stop: logged, and the loop stopped and closed all the same)
                log.exception("stopping the viewer failed")
            self.loop.call_soon_threadsafe(self.loop.stop)
            self.thread.join(timeout=10)
        if not self.thread.is_alive() and not self.loop.is_closed():
            self.loop.close()
