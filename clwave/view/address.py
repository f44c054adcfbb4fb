"""Where the viewer listens and who may reach it (docs/viewer.md §1, "Security"): the port, and whether a host (the
address it binds, or a request's ``Host``) is this machine's loopback, for the Host check against DNS rebinding."""

from __future__ import annotations

import ipaddress
import re
import socket

from ..errors import InputError, whole_number


def check_port(port) -> int:
    """``port`` as an int, or an :class:`InputError` unless it is a whole number from 0 (a free port) to 65535."""
    if not (whole_number(port) and 0 <= port <= 65535):
        raise InputError(f"port={port!r} must be from 0 (a free port) to 65535",
                         cli=f"--port {port} must be from 0 (a free port) to 65535")
    return int(port)


def check_host(host) -> str:
    """``host``, or an :class:`InputError` unless it is the name or address of an interface of this machine, checked
    before any work: "" bound every interface, as 0.0.0.0 does, and printed an address with no host in it; a name
    that does not resolve, or an address of another machine, was refused only once the server started, after the
    volume's reading and transform.  Each of its addresses is bound as the server binds them (asyncio's
    ``create_server``: IPv6 only on IPv6), at a free port, and let go."""
    if not isinstance(host, str) or not host.strip():
        fix = "must name an interface: 127.0.0.1 (this machine only, the default) or one that others reach"
        raise InputError(f"host={host!r} {fix}", cli=f"--host {host!r} {fix}")
    try:
        for family, kind, protocol, _, address in socket.getaddrinfo(host, 0, type=socket.SOCK_STREAM,
                                                                      flags=socket.AI_PASSIVE):
            with socket.socket(family, kind, protocol) as probe:
                if family == socket.AF_INET6:
                    probe.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, True)
                probe.bind(address)
    except (OSError, UnicodeError) as exc:  # gaierror; EADDRNOTAVAIL; a name IDNA cannot encode
        raise host_refused(f"cannot listen on {host} ({getattr(exc, 'strerror', None) or exc})") from None
    return host


def host_refused(why: str) -> InputError:
    """The one line that refuses a host not of this machine: ``why``, then the fix."""
    fix = "name an interface of this machine: 127.0.0.1 (the default) or one that others reach"
    return InputError(f"{why}; host= must {fix}", cli=f"{why}; --host must {fix}")


def is_loopback(host: str) -> bool:
    """Whether ``host`` names this machine's loopback: ``localhost`` (with DNS's trailing dot or not), 127.0.0.0/8,
    ``::1``, or 127.x written as an IPv4-mapped IPv6 address (``::ffff:127.0.0.1``)."""
    if host in ("localhost", "localhost."):
        return True
    try:
        address = ipaddress.ip_address(host)
    except ValueError:
        return False
    mapped = getattr(address, "ipv4_mapped", None)
    return address.is_loopback or (mapped is not None and mapped.is_loopback)


def host_name(host: str) -> str:
    """The name or address of a ``Host`` header, ``name[:port]`` or ``[v6][:port]`` (lower case), "" for anything else
    (read here, not by yarl, which takes ``a@b`` for a user at b and raises on a port past 65535 or a bad IDNA name)."""
    match = re.fullmatch(r"\[([0-9a-fA-F:.]+)\](?::\d+)?|([^:\[\]@]+)(?::\d+)?", host)
    return (match[1] or match[2]).lower() if match else ""
