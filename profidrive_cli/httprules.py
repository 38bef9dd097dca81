"""The rules every HTTP endpoint of pdrive keeps (`sim --control`: sim/control_http.py; `monitor --web`:
monitor/web.py), in one place: how many connections a descriptor limit affords, loopback or a token,
and whether a request comes from somewhere else (DNS rebinding, CSRF). A top-level module: it
imports no layer, so that sim/ and monitor/ both stand on it.
"""

from __future__ import annotations

import ipaddress
import socket
from urllib.parse import urlsplit


def clients_for_limit(nofile: int | None, most: int) -> int:
    """How many connections a server can afford under a descriptor limit `nofile`: a quarter of what
    is left after the process's own (its port, files, Python's: 16), between 2 and `most` -- 12 at a
    limit of 64, 32 (of most 32) at 1,024."""
    if nofile is None or nofile <= 0:
        return most
    return max(2, min(most, (nofile - 16) // 4))


def nofile() -> int | None:
    """The soft limit of open descriptors (None: none, or no such limit: Windows)."""
    try:
        import resource
    except ImportError:                     # (Windows: no such limit)
        return None
    soft = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
    return None if soft == resource.RLIM_INFINITY else int(soft)


def is_loopback(host: str) -> bool:
    if host in ("localhost", ""):
        return host == "localhost"
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def needs_token(host: str) -> bool:
    """A server bound to `host` asks every request for its token: any address but loopback (an empty
    host, 0.0.0.0 and ::, binds every interface)."""
    return not is_loopback(host)


def host_name(hostport: str) -> str:
    """'HOST:PORT', '[V6]:PORT' or 'HOST' -> the host, lower case, without a trailing dot."""
    h = hostport.strip()
    if h.startswith("["):
        h = h[1:].partition("]")[0]
    elif h.count(":") == 1:
        h = h.partition(":")[0]
    return h.lower().rstrip(".")


def names_for(host: str) -> set[str]:
    """The names a Host header may carry for a server bound to `host`: the address itself,
    localhost, 127.0.0.1 and ::1, this machine's name (any IP literal is accepted too: own_host)."""
    names = {host.lower().strip("[]"), "localhost", "127.0.0.1", "::1"}
    try:
        names.add(socket.gethostname().lower())
    except OSError:
        pass
    return names


def own_host(host: str, names: set[str]) -> bool:
    """A Host (or an Origin's host) that names this server: one of `names`, a *.localhost name, an IP
    address. A DNS-rebinding page's Host is its own domain name, never an address."""
    name = host_name(host)
    if name in names or name.endswith(".localhost"):
        return True
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


def foreign(host: str | None, site: str | None, origin: str | None, names: set[str], what: str,
            bound: tuple[str, int] | None = None) -> str | None:
    """Why a request comes from somewhere else (403), or None: its Host header, Sec-Fetch-Site and
    Origin. A request without a Host is checked against `bound` (HOST, PORT), or refused when an
    Origin comes without either. `what`: the server's name in the answer ("monitor")."""
    if host is not None and not own_host(host, names):
        return f"Host {host[:80]!r} is not this {what}"
    if site is not None and site not in ("same-origin", "none"):
        return f"a {site[:20]} request (Sec-Fetch-Site)"
    if origin is None:
        return None
    refused = f"Origin {origin[:80]!r} is not this {what}"
    try:
        o = urlsplit(origin)
        port = o.port
    except ValueError:
        return refused
    if host is None and bound is None:
        return refused
    target = host if host is not None else f"{bound[0]}:{bound[1]}" if bound else ""
    if o.scheme != "http" or o.netloc.lower() != target.strip().lower() \
            or not own_host(o.netloc, names) or (host is None and bound and port != bound[1]):
        return refused
    return None
