"""The viewer's web server (docs/viewer.md §1): aiohttp, one page, one WebSocket per tab.

Every request and socket needs the random token of the printed address (403 without), and on a loopback address a
Host naming this machine; the routes are a fixed set, so a page can never name a file or run anything.  Each tab's
socket holds its own view; frames are rendered one stage at a time on a single render thread (OpenCL work is
serialised and tabs take turns), and a tab's work for a view it has left is dropped between stages and never sent.
"""

from __future__ import annotations

import asyncio
import atexit
import errno
import itertools
import logging
import secrets
import socket
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor
from functools import partial
from importlib import resources
from urllib.parse import urlsplit

from aiohttp import WSCloseCode, WSMsgType, web

from ..device.memory import format_size, parse_cap
from ..model.camera import opening_view
from ..errors import ClwaveError, DeviceMemoryError, InputError, caught_warnings, warn_outside
from ..threads import Abandoned, stop_on
from .address import check_host, check_port, host_name, host_refused, is_loopback
from . import colours, export
from .frames import ViewState, XraySource
from .orientation import patient_world, views
from .shaded import ShadedSource
from .protocol import (MAX_MESSAGE, TOO_BIG, RateLimit, Refused, close_reason, model_id, pack_frame, parse_view,
                       said)

log = logging.getLogger("clwave.view")

#: the page's scripts (index.html loads them in this order, docs/viewer.md §4)
SCRIPTS = ("page.js", "frames.js", "controls.js", "tf.js", "clip.js", "kept.js", "export.js", "viewer.js")
#: the page's files, the only ones served (read once from the package)
STATIC = {"/": ("index.html", "text/html"), "/viewer.css": ("viewer.css", "text/css"),
          **{f"/{name}": (name, "text/javascript") for name in SCRIPTS}}
#: a file's rest is read from the first frame sent (its reading shares the cores and the interpreter with that
#: frame), or this many seconds after the server starts, whichever is first
READ_AFTER = 5.0
#: tabs open at once: each still view under way holds its own image's framebuffers and footprint tables (docs/viewer.md
#: §1), so a socket past these is closed at once (1013, try again later)
MAX_TABS = 8
#: seconds a tab's socket is given to close (the server stopping, a message refused); a tab that does not read (its
#: buffers full) would hold the close for ever, and is dropped after them
CLOSE_SECONDS = 2.0
HEADERS = {"Cache-Control": "no-store", "Referrer-Policy": "no-referrer", "X-Content-Type-Options": "nosniff",
           "Content-Security-Policy": "default-src 'self'; img-src 'self' blob: data:; connect-src 'self'; "
                                      "object-src 'none'; base-uri 'none'; form-action 'none'"}


async def _headers(request, response):
    response.headers.update(HEADERS)


def _caught(call, *args):
    """``(call(*args), the clwave warnings it gave)``, caught on the thread that runs it (render jobs run on threads,
    where ``warnings.catch_warnings`` would catch the other threads' too: :func:`~clwave.errors.caught_warnings`)."""
    with caught_warnings() as caught:
        return call(*args), caught


def memory_shares(device_memory, shaded: bool) -> dict:
    """The device memory (bytes; None: the device's) each renderer of a server may hold, ``device_memory`` shared
    out (docs/viewer.md §1): half to the X-ray views and half to the shaded ones where both are served."""
    cap = parse_cap(device_memory)
    if cap is None:
        return dict(xray=None, shaded=None)
    xray = cap // 2 if shaded else cap
    return dict(xray=xray, shaded=cap - xray if shaded else None)


class ViewServer:
    """Serves views of one wavelet model: the X-ray source always, the shaded one for a scalar or an RGBA model.

    ``size`` (H, W) is the full image; ``tolerance`` the shaded frames' when still; ``transfer_function`` a scalar
    model's shaded views' from the first frame (None: the model's own, or grey), where the page's editor starts.
    ``device_memory`` (bytes or a size such as "2GiB"; None: the device's) caps the device memory of all the
    server's renderers together (:func:`memory_shares`).
    :meth:`start` binds ``host:port`` (port 0: a free one) inside a running event loop; :attr:`url` is the address
    with the token.
    """

    def __init__(self, model, size=(512, 512), tolerance=1e-2, device=None, host="127.0.0.1", port=0,
                 transfer_function=None, device_memory=None, origin=None):
        from .export import Origin
        from .prefix import PrefixFirst

        opened = model if isinstance(model, PrefixFirst) else None
        self.wv = opened.prefix if opened else model
        self.home = opening_view(self.wv)  # the page's first view and its "fit" (a double click)
        # a file's recorded error against its input is its whole model's, not that of a view keeping fewer (--keep)
        self.model_error = None if opened is None else dict(rms=opened.model_error, whole=opened.keep is None)
        self.host, self.port, self.device = check_host(host), check_port(port), device
        self.local = is_loopback(host)  # then a request's Host must name this machine too (DNS rebinding)
        self.device_memory = parse_cap(device_memory)
        self.shares = memory_shares(device_memory, shaded=self.wv.channels == 1 or self.wv.classified)
        self.token = secrets.token_urlsafe(24)
        self.origin = origin or Origin()  # how the model was made: a view's command line reads it so (export.py)
        self.saving = asyncio.Lock()  # one image saved at a time (export.serve)
        # set by stop() (or, for the reader, at the interpreter's exit): the reader stops between its steps, for a
        # daemon thread stopped by the interpreter inside a read would keep h5py's lock and the exit would wait for it
        # for ever; the render and build threads' launches and set-ups stop at their next checkpoint (threads.stop_on)
        # by stop() only: an exit joins pool threads before its atexit hooks (docs/viewer.md §1)
        self._stop = threading.Event()
        self.pool = ThreadPoolExecutor(1, thread_name_prefix="clwave-view-render", initializer=stop_on,
                                       initargs=(self._stop,))
        # what a source makes before its first frame (the ray tracer's bricks) is made here, so that the render
        # thread goes on serving every tab meanwhile
        self.builder = ThreadPoolExecutor(1, thread_name_prefix="clwave-view-build", initializer=stop_on,
                                          initargs=(self._stop,))
        self._builds = {}  # mode -> the Future of its source's prepare()
        self.sessions = {}  # id -> Session, the open sockets
        self._ids = itertools.count(1)
        self._runner = self.loop = None
        self.stopping = False
        # a file's prefix: the rest is read on a thread of its own, started by the first frame sent (or READ_AFTER
        # seconds after start), and swapped in on the render thread (docs/viewer.md §2)
        self.whole = None if opened is None or opened.complete else Future()
        self._reader = None if self.whole is None else threading.Thread(
            target=self._read_whole, args=(opened,), name="clwave-view-read", daemon=True)
        self._starting = threading.Lock()  # the reader is started from the event loop or the shaded set-up
        self._in_file = threading.Event()  # set from the reader's start until it has done with the file (h5py)
        self.coarse_first = False  # set by _prepare
        self.failure = None  # why the rest of a file could not be served (the page's model figures say it)
        self.warned = set()  # the renderers' warnings logged so far (each once a server: a drag repeats them)
        try:
            self.sources, caught = self.pool.submit(_caught, self._prepare, self.wv, size, tolerance, opened,
                                                    transfer_function).result()
        except DeviceMemoryError as exc:
            raise self.explain(exc, "xray") from None
        for warning in caught:  # the caller's, as if it were made here
            warn_outside(warning)
        self.patient = patient_world(self.wv, self.origin)
        for source in self.sources.values():  # its frames' edges are labelled R, A, S... or +x, +y, +z (orientation.py)
            source.patient = self.patient
        self.pages = {path: (resources.files(__package__).joinpath("static", name).read_text(), mime)
                      for path, (name, mime) in STATIC.items()}

    def _prepare(self, wv, size, tolerance, opened, transfer_function) -> dict:
        """The sources, made on the render thread, with one frame of each kind drawn (kernels built, warm)."""
        from ..splat.renderer import SplatRenderer

        xray = XraySource(wv, size, SplatRenderer(wv, device=self.device, device_memory=self.shares["xray"]),
                          complete=self.whole is None)
        for _ in xray.frames(self.initial_view(xray, moving=True), xray.pacing()):  # the kernels built (one build
            pass                                                                   # serves every size, stages.py)
        # the largest X-ray image served, a still view at ``size`` (the frames above are smaller): refused now, not
        # on the page (the 128x128 auto-window image is checked as XraySource makes it)
        xray.r.begin(xray.camera(self.initial_view(xray)))
        sources = dict(xray=xray)
        if wv.channels == 1 or wv.classified:  # a scalar model through a transfer function at render time, or RGBA
            # a whole file (not a part of it, keep=) is traced in stages: its coarse stage at once, read from the file;
            # the full one from the model held (the prefix, where it is all of the file) or read for the X-ray views
            path = opened.path if opened is not None and opened.keep is None else None
            self.coarse_first = path is not None  # the reading thread reads the coarse stage's share first
            sources["shaded"] = ShadedSource(wv, size, tolerance, device=self.device,
                                             device_memory=self.shares["shaded"], path=path,
                                             whole=None if self.whole is None else self.whole_model,
                                             coarse=None if path is None else opened.coarse,
                                             upgraded=self.upgraded,
                                             transfer_function=transfer_function)
        return sources

    def read_whole(self):
        """Start reading the rest of a file opened by its prefix (once, from any thread; nothing to read otherwise)."""
        with self._starting:
            if self._reader is not None and self._reader.ident is None and not self._stop.is_set():
                atexit.register(self._stop_reading)
                self._in_file.set()
                self._reader.start()

    def _stop_reading(self):
        """Stop reading the rest (by :meth:`stop`, or at the interpreter's exit): the reader stops after the step
        under way, waited for while it reads the file (h5py's reads are bounded: a daemon thread stopped inside
        one would keep h5py's lock), not while it ranks what it read; the whole model, not read, is
        :class:`Abandoned` for whoever waits for it (the shaded views' set-up): the reader's to settle, or this
        stop's where the reader never starts (one side only: a check and a set from each raced)."""
        self.stopping = True  # its Abandoned is no failure to log
        with self._starting:  # read_whole starts no reader after this
            self._stop.set()
            started = self._reader is not None and self._reader.ident is not None
        if started and self._in_file.is_set():
            log.info("stopping: waiting for the read of the file under way")
            self._reader.join()
        if self.whole is not None and not started and not self.whole.done():
            self.whole.set_exception(Abandoned("the viewer stopped before the rest of the file was read"))

    def whole_model(self):
        """The whole model of a file opened by its prefix (its reading started if it has not been, and waited for):
        the shaded views' tracer takes it rather than reading the file again."""
        self.read_whole()
        return self.whole.result()

    def _read_whole(self, opened):
        """On the reading thread: the whole model, ranked with the prefix's coefficients first, then put into the
        prefix's renderer on the render thread."""
        from ..splat.ranked import ranked_groups
        from .prefix import part_rows, prefix_first

        def step():  # between two steps: stop() given
            if self._stop.is_set():
                raise Abandoned("the viewer stopped")

        start = time.perf_counter()
        try:
            try:
                wv = self.logged(lambda: opened.whole(coarse_first=self.coarse_first, stop=self._stop))
            finally:
                self._in_file.clear()  # nothing after this reads the file
            step()
            rows = part_rows(wv, opened.prefix)  # a file replaced meanwhile: no view gets it (one volume a page)
            step()
            self.whole.set_result(wv)
            read = time.perf_counter() - start
            groups = ranked_groups(wv, prefix_first(wv, opened.prefix, rows))
            step()
        except Exception as exc:  # noqa: BLE001  (the prefix goes on being served)
            if not self.whole.done():
                self.whole.set_exception(exc)
            self.upgraded("xray", exc)
            return
        log.info("read the whole of %s in %.1f s (%s coefficients), ranked it in %.1f s", opened.path.name, read,
                 f"{groups[0]['count']:,}", time.perf_counter() - start - read)
        try:
            self.pool.submit(self._swap, wv, groups)
        except RuntimeError:  # the server has stopped meanwhile
            pass

    def _swap(self, wv, groups):
        """On the render thread, between two stages: the whole model in place of the prefix."""
        try:
            self.sources["xray"].swap(wv, groups)
        except ValueError as exc:  # a ranking that does not begin with the prefix's: logged, the prefix goes on
            self.upgraded("xray", exc)
            return
        self.wv = wv
        log.info("serving the whole model")
        self.upgraded("xray")

    def upgraded(self, mode, failure=None):
        """A source has a better model now (from any thread): each tab hears it, and one whose still view of that
        mode has had no final frame renders it again.  ``failure``: making it failed (logged, and each tab shown the
        line, unless the server is stopping meanwhile); the source goes on as it was, and an X-ray one's file is no
        longer being read (the page's model figures)."""
        if failure is not None:
            if self.stopping:
                return
            log.error("making the whole model for %s views failed: %s", mode, failure)
            reason = said(failure)
            failure = f"making the whole model for the {'X-ray' if mode == 'xray' else mode} views failed " \
                      f"(they go on with what they have): {reason}"
            if mode == "xray":  # the prefix is the model served from now on: its still views end final
                self.failure, self.sources["xray"].complete = reason, True
        if self.loop is not None:
            try:
                self.loop.call_soon_threadsafe(
                    lambda: [s.upgraded(mode, failure) for s in list(self.sessions.values())])
            except RuntimeError:  # the server has stopped meanwhile (its loop closed): no tab to tell
                pass

    def explain(self, exc: BaseException, mode: str) -> BaseException:
        """``exc`` as the page (or the caller) should read it: a renderer refusing within its share of the viewer's
        device memory names the share and the viewer's cap (:func:`memory_shares`)."""
        if self.device_memory is None or not isinstance(exc, DeviceMemoryError):
            return exc
        views = "X-ray" if mode == "xray" else "shaded"
        total = format_size(self.device_memory)
        given, small, why = str(exc).partition(" is too small: ")  # a renderer's "device_memory=S is too small: ..."
        if small:
            words = f"too small for this viewer: its {views} views get {given.partition('=')[2]} of it " \
                    f"(docs/viewer.md §1), and {why}"
            cli = words.replace("render a smaller image", "a smaller --size")
            return DeviceMemoryError(f"device_memory={total} is {words}", cli=f"--device-memory {total} is {cli}")
        share = f"the {views} views' share of it (docs/viewer.md §1)"
        return DeviceMemoryError(f"{exc} (within {share}: device_memory={total})",
                                 cli=f"{exc.cli_message()} (within {share}: --device-memory {total})")

    def warnings(self, caught, name) -> list:
        """The lines of ``caught``, clwave's warnings of one render job for ``name`` (a tab), each logged once."""
        lines = [str(w) for w in caught]
        for line in lines:
            if line not in self.warned:
                self.warned.add(line)
                log.warning("%s: %s", name, line)
        return lines

    def logged(self, call, *args, notes=None):
        """``call(*args)``, a job of the render or build thread that is no tab's frame (a save, a tracer's build),
        its clwave warnings logged once each, and added to the list ``notes`` where one is given (a save's)."""
        value, caught = _caught(call, *args)
        lines = self.warnings(caught, "the viewer")
        if notes is not None:
            notes += [line for line in lines if line not in notes]
        return value

    def prepared(self, source):
        """The Future of ``source.prepare()`` on the build thread (started on first call)."""
        if source.mode not in self._builds:
            self._builds[source.mode] = asyncio.wrap_future(self.builder.submit(self.logged, source.prepare))
        return self._builds[source.mode]

    def initial_view(self, source, moving=False) -> ViewState:
        return ViewState(seq=0, **self.home, zoom=1.0, mode=source.mode, detail=1.0, window=None, moving=moving,
                         background=0.0, shading=True)

    # ------------------------------------------------------------------ HTTP
    @web.middleware
    async def _token(self, request, handler):
        given = request.query.get("token", "")
        if not secrets.compare_digest(given.encode(), self.token.encode()):
            log.warning("refused %s %s from %s: no valid token", request.method, request.path, request.remote)
            raise web.HTTPForbidden(text="403: open the address clwave printed, with its ?token=...\n")
        # a page of another site whose name was made to point here (DNS rebinding) names that site (as Jupyter checks)
        if self.local and not is_loopback(host_name(request.host)):
            log.warning("refused %s %s from %s: Host %r is not this machine", request.method, request.path,
                        request.remote, request.host)
            raise web.HTTPForbidden(text="403: open the address clwave printed (127.0.0.1, ::1 or localhost)\n")
        return await handler(request)

    async def _page(self, request):
        text, mime = self.pages[request.path]
        return web.Response(text=text.replace("{{token}}", self.token), content_type=mime)

    def app(self) -> web.Application:
        app = web.Application(middlewares=[self._token], client_max_size=MAX_MESSAGE)
        app.on_response_prepare.append(_headers)  # on every response, a refusal's too (403, 404, 413)
        app.router.add_get("/ws", self._socket)
        app.router.add_post("/export", partial(export.serve, self, image=False))
        app.router.add_post("/image", partial(export.serve, self, image=True))
        for path in STATIC:
            app.router.add_get(path, self._page)
        return app

    async def start(self):
        self.loop = asyncio.get_running_loop()
        if self._reader is not None:
            self.loop.call_later(READ_AFTER, self.read_whole)
        self._runner = web.AppRunner(self.app(), access_log=None, handle_signals=False)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.host, self.port)
        try:
            await site.start()
        except OSError as exc:  # a port in use, a host not of this machine
            why = f"cannot listen on {self.host}:{self.port} ({exc.strerror or exc})"
            if isinstance(exc, socket.gaierror) or exc.errno == errno.EADDRNOTAVAIL:  # the host's, not the port's
                raise host_refused(why) from None  # (check_host found it bound before: it is not any more)
            raise InputError(f"{why}; choose another port=, or port=0 for a free one",
                             cli=f"{why}; choose another --port, or leave it out for a free one") from None
        self.port = self._runner.addresses[0][1]
        return self.url

    async def stop(self):
        """Close every tab and the server; stop reading a file's rest and building the shaded views' tracer (both
        waited for), and give up the set-up of a file's full stage, so that no thread of the server outlives it by
        more than the step under way."""
        self.stopping = True
        # the page says the server is gone (static/viewer.js, disconnected); all at once, each within CLOSE_SECONDS
        await asyncio.gather(*(session.close(WSCloseCode.GOING_AWAY, "the viewer stopped")
                               for session in list(self.sessions.values())))
        if self._runner is not None:
            await self._runner.cleanup()
        self._stop_reading()
        atexit.unregister(self._stop_reading)
        shaded = self.sources.get("shaded")
        if shaded is not None:
            shaded.stop()
        self.pool.shutdown(wait=False, cancel_futures=True)
        # the shaded views' set-up under way stops at its next slab (the build thread's stop_on event, set above, and
        # ShadedSource.stop for a file's full stage): waited for, as the reader is
        self.builder.shutdown(wait=True, cancel_futures=True)
        self.sources = {}  # their renderers' memory let go with the last frame under way

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/?token={self.token}"

    # ------------------------------------------------------------------ sockets
    @staticmethod
    def check_origin(request):
        """403 for a socket or a POST whose Origin is another site's page, even with the token."""
        origin = request.headers.get("Origin")
        if origin and urlsplit(origin).netloc != request.host:
            log.warning("refused %s %s from %s: origin %s is not this server", request.method, request.path,
                        request.remote, origin)
            raise web.HTTPForbidden(text="403: another origin\n")

    async def _socket(self, request):
        self.check_origin(request)
        ws = web.WebSocketResponse(max_msg_size=MAX_MESSAGE, heartbeat=30.0)
        await ws.prepare(request)
        session = Session(self, ws, f"tab {next(self._ids)} ({request.remote})", request.transport)
        if len(self.sessions) >= MAX_TABS:
            log.warning("refused %s: %d tabs are open", session.name, MAX_TABS)
            await session.close(WSCloseCode.TRY_AGAIN_LATER, f"{MAX_TABS} tabs have this viewer open already: close "
                                                             f"one, then reload this page")
            return ws
        self.sessions[id(session)] = session
        try:
            await session.run()
        finally:
            del self.sessions[id(session)]
        return ws

    def hello(self) -> dict:
        xray = self.sources["xray"]
        from ..model.transfer import TransferFunction

        shaded = self.sources.get("shaded")
        return dict(type="hello", modes=list(self.sources), mode="shaded" if shaded and shaded.chosen else "xray",
                    size=list(xray.size), window=list(xray.auto_window),
                    presets=list(TransferFunction.PRESETS), colour_maps=colours.page_tables(),
                    tf=shaded.start_figures() if shaded else None,
                    capabilities={mode: s.capabilities for mode, s in self.sources.items()}, model=self.model(),
                    model_id=model_id(self.wv), views=views(self.patient), patient=self.patient, home=self.home)

    def model(self) -> dict:
        """The model's figures for the page; ``reading``: a file's prefix, the rest being read; ``failure``: why the
        rest's reading failed (None: it did not); ``box``: the world box of its content, the span of the crop
        sliders; ``error``: a file's ``rms`` error against its input (None: not recorded) and whether the view
        holds the ``whole`` file (None: no file)."""
        from ..model.camera import _content_box

        wv, xray = self.wv, self.sources["xray"]
        return dict(shape=list(wv.shape), channels=wv.channels, coefficients=xray.r.count, voxels=wv.n_voxels,
                    box=[[float(c) for c in corner] for corner in _content_box(wv)],
                    levels=wv.levels, wavelets=sorted({g.wavelet.name for g in wv.groups}),
                    transfer_function=(wv.transfer_function or {}).get("name"), value_range=wv.value_range,
                    reading=not xray.complete and self.failure is None, failure=self.failure, error=self.model_error)


class Session:
    """One tab: its latest view, and the loop that renders it stage by stage while it stays the latest."""

    def __init__(self, server: ViewServer, ws, name: str, transport):
        self.server, self.ws, self.name, self.transport = server, ws, name, transport
        self.state, self.seq, self.limit = None, -1, RateLimit()
        self.wake = asyncio.Event()
        self.sent = self.dropped = 0
        self.paces = {}  # mode -> this tab's pacing of its frames (frames.XrayPace, shaded.ShadedPace)
        self.news = set()  # modes whose source has a better model since this tab's last view began
        self.failures = {}  # mode -> the line saying its better model could not be made (the page shows it)
        self.rendered, self.final = None, False  # the last view rendered, and whether its final frame was sent
        self.histogram = None  # the last histogram of the model's values sent

    def upgraded(self, mode, failure=None):
        """The ``mode`` source has a better model (a file's whole, swapped in for its prefix), or ``failure`` (a line
        for the page) says why it could not be made."""
        if failure is None:
            self.news.add(mode)
        else:
            self.failures[mode] = failure
        self.wake.set()

    async def run(self):
        ws, modes = self.ws, tuple(self.server.sources)
        await ws.send_json(self.server.hello())
        renderer = asyncio.create_task(self._render())
        try:
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    try:
                        self.limit.take()
                        self.state = parse_view(msg.data, self.seq, modes)
                    except Refused as refused:
                        await self.refuse(refused)
                        break
                    self.seq = self.state.seq
                    self.wake.set()
                elif msg.type == WSMsgType.BINARY:
                    await self.refuse(Refused("a binary message (a page sends JSON text only)"))
                    break
                elif msg.type == WSMsgType.ERROR:
                    exc = ws.exception()
                    code = getattr(exc, "code", None)
                    log.warning("closed %s: %s", self.name, "a message over the size limit" if code == TOO_BIG
                                else exc)
                    break
        finally:
            self.state = None
            renderer.cancel()

    async def _prepared(self, source, state) -> bool:
        """Wait for ``source`` to be made on the build thread, or for a newer view (False: go to it); the page
        hears what is being made, or why it failed."""
        building = self.server.prepared(source)
        if not building.done():
            await self.ws.send_json(dict(type="status", seq=state.seq, message="preparing the ray tracer (its "
                                         "bricks) for the first shaded view…"))
            newer = asyncio.ensure_future(self.wake.wait())
            try:
                await asyncio.wait({building, newer}, return_when=asyncio.FIRST_COMPLETED)
            finally:  # the tab closed meanwhile too: no task left pending
                newer.cancel()
            if not building.done():
                return False
        if building.exception() is not None:
            exc = building.exception()
            if not isinstance(exc, ClwaveError):
                log.error("%s: preparing the %s view failed", self.name, source.mode, exc_info=exc)
            message = said(self.server.explain(exc, source.mode))
            await self.ws.send_json(dict(type="error", seq=state.seq, message=message))
            return False
        return self.state is state  # else the newer view is waiting (wake is set)

    async def refuse(self, refused: Refused):
        log.warning("closed %s: %s", self.name, refused)
        await self.close(refused.code, str(refused))

    async def close(self, code: int, reason: str):
        """Close the socket with ``code`` and ``reason``, or drop it where its close is not done within
        :data:`CLOSE_SECONDS` (a tab that does not read, its buffers full, would hold the close for ever)."""
        try:
            await asyncio.wait_for(self.ws.close(code=code, message=close_reason(reason)), CLOSE_SECONDS)
        except asyncio.TimeoutError:
            log.warning("dropped %s: its close was not read within %g s", self.name, CLOSE_SECONDS)
            self.transport.abort()

    async def _render(self):
        loop, pool = asyncio.get_running_loop(), self.server.pool
        while True:
            await self.wake.wait()
            self.wake.clear()
            news, self.news = self.news, set()
            failures, self.failures = self.failures, {}
            if "xray" in news or "xray" in failures:  # the whole model is in, or will not be: the page's figures
                await self.ws.send_json(dict(type="model", model=self.server.model()))
            for failure in failures.values():  # on the page's status line, whatever view it shows (no seq: a view
                await self.ws.send_json(dict(type="error", message=failure))  # moved to meanwhile shows it too)
            state = self.state
            # a wake by news alone renders the view again where its mode has news and it has had no final frame
            if state is None or state is self.rendered and (self.final or state.mode not in news):
                continue
            self.rendered, self.final = state, False
            notes = []  # the renderer's warnings of this view so far: every later frame of it carries them
            source = self.server.sources[state.mode]
            waited = 0.0  # seconds the view waited for its source's build (the shaded tracer's bricks)
            if not source.ready():
                began = time.perf_counter()
                if not await self._prepared(source, state):
                    continue
                waited = time.perf_counter() - began
            if state.mode not in self.paces:
                self.paces[state.mode] = source.pacing()
            values = source.histogram()  # the page's editor draws it: sent once a tracer
            if values is not None and values is not self.histogram:
                self.histogram = values
                await self.ws.send_json(dict(type="histogram", **values))
            frames = source.frames(state, self.paces[state.mode])
            try:
                while self.state is state:
                    frame, caught = await loop.run_in_executor(pool, _caught, next, frames, None)
                    notes += [line for line in self.server.warnings(caught, self.name) if line not in notes]
                    if frame is None:
                        break
                    if self.state is not state:  # the tab has moved on while this stage rendered
                        self.dropped += 1
                        break
                    # the time since the view counts the build it waited for, said apart (build_seconds)
                    figures = dict(frame.figures, elapsed=frame.figures["elapsed"] + waited, build_seconds=waited)
                    if notes:  # the status line's note: the source's own (why an image is blank), then the warnings
                        figures["note"] = " · ".join(filter(None, [figures.get("note"), *notes]))
                    await self.ws.send_bytes(pack_frame(figures, frame.data, frame.mime))
                    self.sent += 1
                    self.final = frame.figures["final"]
                    self.server.read_whole()  # a file's rest, once the first frame is out
            except ClwaveError as exc:  # e.g. an image too large for the device: the page shows the line
                message = str(self.server.explain(exc, state.mode))
                await self.ws.send_json(dict(type="error", seq=state.seq, message=message))
            except ConnectionResetError as exc:  # the socket went away mid-send
                log.info("%s: %s", self.name, exc)
                return
            except Exception as exc:  # a bug: logged in full, one line to the page, the tab goes on
                log.exception("%s: rendering view %d failed", self.name, state.seq)
                await self.ws.send_json(dict(type="error", seq=state.seq, message=f"internal error "
                                             f"({type(exc).__name__}); this is a bug in clwave, see the server's log"))
            finally:
                await asyncio.shield(loop.run_in_executor(pool, frames.close))
