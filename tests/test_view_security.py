"""Who may connect to the viewer, and tabs that misbehave (docs/viewer.md §1, Security): a page of another site
pointed here by DNS rebinding, more tabs than the server holds, and a tab that never reads its socket while the
server stops.  The messages themselves: tests/test_view.py."""

import asyncio
import base64
import json
import os
import socket
import threading
import time

import aiohttp
import clwave
from clwave.view import server as view_server
from clwave.view import view
from test_view import BASE, run, socket_url, viewer  # noqa: F401  (viewer: the module's fixture)

#: seconds a stop or a refusal takes at most with a tab that does not read (CLOSE_SECONDS and the stage under way)
WITHIN = 20


def test_a_page_of_another_site_pointed_here_is_refused_even_with_the_token(viewer):  # noqa: F811
    """A site whose name resolves to 127.0.0.1 after its page has loaded (DNS rebinding) is same-origin with this
    server in the browser: its requests name that site in Host, and a server on a loopback address refuses them
    (as Jupyter does); this machine's names are served."""
    port, query = viewer.server.port, "?token=" + viewer.server.token

    served = (f"localhost:{port}", f"127.0.0.1:{port}", f"127.0.0.2:{port}", f"[::1]:{port}", f"LOCALHOST:{port}")
    refused = (f"evil.example:{port}", f"127.0.0.1.evil.example:{port}", f"evil.example@127.0.0.1:{port}",
               f"[::1].evil.example:{port}", f"127.0.0.1:1@evil.example:{port}", "xn--", "", f"::1:{port}", "[::1")

    async def go():
        async with aiohttp.ClientSession() as s:
            statuses = {}
            for host in served + refused:
                for path in ("/", "/viewer.js", "/ws"):
                    r = await s.get(f"http://127.0.0.1:{port}{path}{query}", headers={"Host": host})
                    statuses[host, path] = r.status
            return statuses
    statuses = run(go())
    for (host, path), status in statuses.items():  # 400: a socket's path past the checks, no WebSocket asked for
        assert status == (403 if host in refused else 400 if path == "/ws" else 200), (host, path, status)


def test_tabs_past_the_most_are_closed_at_once_with_a_line(viewer):  # noqa: F811
    """Each tab's still view holds its own image's tables until its final frame: a socket past MAX_TABS is closed
    with 1013 (try again later) and a reason saying what to do; once a tab has gone, a new one is served."""
    most = view_server.MAX_TABS

    async def go():
        async with aiohttp.ClientSession() as s:
            tabs = [await s.ws_connect(socket_url(viewer)) for _ in range(most)]
            for ws in tabs:
                assert (await ws.receive_json(timeout=60))["type"] == "hello"
            extra = await s.ws_connect(socket_url(viewer))
            msg = await extra.receive(timeout=60)
            refused = (msg.type, extra.close_code, msg.extra)
            await tabs.pop().close()
            for _ in range(100):  # the server hears the close
                if len(viewer.server.sessions) < most:
                    break
                await asyncio.sleep(0.05)
            again = await s.ws_connect(socket_url(viewer))
            hello = await again.receive_json(timeout=60)
            for ws in tabs + [again]:
                await ws.close()
            return refused, hello
    (kind, code, reason), hello = run(go())
    assert kind == aiohttp.WSMsgType.CLOSE and code == 1013, (kind, code, reason)
    assert reason == f"{most} tabs have this viewer open already: close one, then reload this page"
    assert hello["type"] == "hello"


def deaf_tab(server, rcvbuf=4096):
    """A tab that sends views and never reads (a frozen page, a stalled network): a socket of its own with a small
    receive buffer, the WebSocket handshake written by hand and its answer never read."""
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)  # before the connection: its window stays small
    sock.connect(("127.0.0.1", server.port))
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall(f"GET /ws?token={server.token} HTTP/1.1\r\nHost: 127.0.0.1:{server.port}\r\nUpgrade: websocket\r\n"
                 f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n".encode())

    def send(text):  # a masked text frame (RFC 6455 §5.2), its mask zero: the payload as it is
        data = text.encode()
        assert 126 <= len(data) < 1 << 16
        sock.sendall(bytes([0x81, 0x80 | 126]) + len(data).to_bytes(2, "big") + bytes(4) + data)
    return sock, send


def fill(server, send):
    """Views to a deaf tab until the server's send to it waits (a frame fills what the kernel holds for the tab)."""
    for seq in range(1, 4):
        send(json.dumps(dict(BASE, seq=seq, azimuth=10.0 * seq)))
    deadline = time.monotonic() + 60
    while not any(s.transport.get_write_buffer_size() for s in list(server.sessions.values())):
        assert time.monotonic() < deadline, "the tab's buffers never filled"
        time.sleep(0.05)


def test_a_stop_drops_a_tab_that_does_not_read_within_seconds(monkeypatch):
    """A tab whose buffers are full (it does not read) cannot take the server's close: the stop closes the other
    tabs and drops it after CLOSE_SECONDS, not waiting for it for ever (it did: `clwave view` never ended)."""
    pack = view_server.pack_frame
    monkeypatch.setattr(view_server, "pack_frame", lambda *a: pack(*a) + bytes(8 << 20))  # the buffers fill at once
    v = view(clwave.phantom("hydrogen", n=16), size=(16, 16), keep=0.5)
    sock, send = deaf_tab(v.server)
    closing = threading.Thread(target=v.close, daemon=True)
    try:
        fill(v.server, send)
        closing.start()
        closing.join(timeout=WITHIN)
        assert not closing.is_alive(), "the stop waited for a tab that does not read"
        assert not v._background.thread.is_alive() and not v.server.sessions
    finally:
        sock.close()
        if closing.ident is None:  # failed before the stop
            v.close()


def test_a_refused_tab_that_does_not_read_is_dropped(viewer, monkeypatch):  # noqa: F811
    """A refusal's close to a tab whose buffers are full is given up after CLOSE_SECONDS and the socket dropped (it
    waited for ever, the tab's session kept)."""
    pack = view_server.pack_frame
    monkeypatch.setattr(view_server, "pack_frame", lambda *a: pack(*a) + bytes(8 << 20))
    before = len(viewer.server.sessions)
    sock, send = deaf_tab(viewer.server)
    try:
        fill(viewer.server, send)
        send("not json".ljust(200))
        deadline = time.monotonic() + WITHIN
        while len(viewer.server.sessions) > before:
            assert time.monotonic() < deadline, "the refused tab was never dropped"
            time.sleep(0.05)
    finally:
        sock.close()
