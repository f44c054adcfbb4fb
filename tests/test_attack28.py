"""The command line's option values and the viewer's routes under hostile input (docs/known-gaps.md §15,
attack28): each failure class found, pinned by one case.  Every refusal is one line on stderr, exit 2, before the
input is read where the value alone is wrong (a missing input file then is never reached) and with no file left."""

import asyncio

import aiohttp
import pytest

import clwave
from clwave.cli import main
from clwave.view import view
from clwave.view.server import HEADERS

MISSING = "no-such-volume.npy"  # read after the options are checked: a value refused first never reaches it


def refused(capsys, argv, words):
    """``clwave argv`` exits 2 with one line naming ``words``."""
    assert main(argv) == 2, argv
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("clwave: error: ") and words in err[0], (argv, err)


def test_every_response_of_the_viewer_carries_its_headers_refusals_too():
    """A 403, 404, 405, 400 or 413 came without no-store, nosniff, the CSP or no-referrer (the page's did)."""
    async def go(v):
        base, token = v.url.split("/?")[0], v.server.token
        requests = [("GET", "/viewer.js", b"", 403), ("GET", f"/nothing?token={token}", b"", 404),
                    ("GET", f"/export?token={token}", b"", 405), ("POST", f"/export?token={token}", b"[]", 400),
                    ("POST", f"/image?token={token}", b"x" * 10_000, 413), ("GET", f"/?token={token}", b"", 200)]
        async with aiohttp.ClientSession() as s:
            for method, path, body, status in requests:
                async with s.request(method, base + path, data=body) as r:
                    assert r.status == status, path
                    assert {k: r.headers.get(k) for k in HEADERS} == HEADERS, (status, path)

    with view(clwave.phantom("hydrogen", n=16), size=32, keep=0.2) as v:
        asyncio.run(go(v))


def test_a_host_that_names_no_interface_is_refused_naming_the_host(capsys):
    """--host '' bound every interface and printed "http://:PORT/?token=..."; a name that does not resolve was told to
    choose another --port."""
    refused(capsys, ["view", MISSING, "--host", ""], "--host '' must name an interface")
    with pytest.warns(UserWarning, match="listens on nan"), \
            pytest.raises(clwave.InputError, match=r"cannot listen on nan:0 \(.+\); host= must name an interface"):
        view(clwave.phantom("hydrogen", n=8), size=16, host="nan").close()
