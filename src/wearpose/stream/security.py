"""Who may talk to the streaming server, and how much (``docs/streaming.md``, *Security*).

The opening handshake of every WebSocket connection (and ``GET /stats``) is checked by
:meth:`AccessPolicy.check`, in this order; the first failing rule refuses it:

1. **Origin** (what a browser sends; the library's own check,
   ``websockets.ServerProtocol.process_origin``, against :meth:`AccessPolicy.origins`): no
   ``Origin`` header (a non-browser client), a *same-host page* (``http://127.0.0.1:P``,
   ``http://localhost:P``, ``http://[::1]:P`` for the server's port and the viewer's ports) or
   an origin added with ``--allow-origin`` passes; any other origin is refused with HTTP 403,
   whatever token it presents.
2. **Host** (on a loopback bind only): the ``Host`` header must name the loopback interface,
   else 403. A DNS-rebinding page (``evil.example`` resolved to 127.0.0.1) reaches the socket
   with the browser's same-origin rules on its side; its ``Host`` header gives it away.
3. **Token** (``?token=...`` query parameter, or ``Authorization: Bearer ...`` header): a
   presented token must be the server's (else HTTP 401). Without one the request is refused
   (401) when the token is *required*: on any non-loopback bind, with ``require_token``, and
   always for an origin admitted by ``--allow-origin`` (a cross-site page must be both allowed
   and given the token). Otherwise (loopback, same-host or no Origin) the token is optional.

Per connection, after the handshake: :class:`TokenBucket` (messages per second) and
:class:`Throttle` (how many error replies a misbehaving connection gets).
"""

from __future__ import annotations

import http
import ipaddress
import re
import secrets
import time
import urllib.parse
from dataclasses import dataclass, field
from typing import Any, Sequence

from websockets.exceptions import InvalidHandshake

from wearpose.errors import ConfigError
from wearpose.stream.packets import MAX_MESSAGE_BYTES

#: Ports of same-host pages allowed by default besides the server's own: the live viewer's.
VIEWER_PORTS = (8080,)
#: Names of the loopback interface as they appear in Origin and Host headers.
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]")
#: Shortest token ``--token`` accepts (``secrets.token_urlsafe(32)`` gives 43 characters).
MIN_TOKEN_CHARS = 16
_TOKEN_CHARS = re.compile(r"[A-Za-z0-9_\-]+")


def is_loopback_host(host: str) -> bool:
    """True when ``host`` (a bind address or name) is only reachable from this machine.

    ``localhost`` and loopback IPs (127.0.0.0/8, ::1) are; ``""``, ``0.0.0.0``, ``::``, LAN
    addresses and any other name are not (a name might resolve to a public interface)."""
    h = host.strip().strip("[]").lower()
    if h == "localhost":
        return True
    try:
        return ipaddress.ip_address(h).is_loopback
    except ValueError:
        return False


def token_required(host: str, require_token: bool = False) -> bool:
    """Whether a client without an ``Origin`` header, or a same-host page, must present the
    token: always on a non-loopback bind (anyone on the network can reach the port), on
    loopback only when asked (``require_token``, ``wearpose serve --require-token``)."""
    return bool(require_token) or not is_loopback_host(host)


def new_token() -> str:
    """A fresh access token: 32 random bytes, URL-safe base64 (43 characters)."""
    return secrets.token_urlsafe(32)


def check_token(token: str, option: str = "--token") -> str:
    """``token`` if it is usable as an access token, else ConfigError naming ``option``."""
    if len(token) < MIN_TOKEN_CHARS or not _TOKEN_CHARS.fullmatch(token):
        raise ConfigError(f"{option}: expected at least {MIN_TOKEN_CHARS} characters from A-Z a-z 0-9 _ - "
                          f"(it travels in a URL), got {len(token)} characters; leave it out to get a random one")
    return token


def normalise_origin(origin: str, option: str = "--allow-origin") -> str:
    """``origin`` in the form browsers send: ``scheme://host[:port]``, lower case, no default
    port, no path (``HTTP://Example.com:80/`` -> ``http://example.com``).

    Raises:
        ConfigError: not an http(s) origin (names ``option`` and the expected form).
    """
    u = urllib.parse.urlsplit(origin.strip())
    try:
        port = u.port
    except ValueError:
        port = -1
    if u.scheme.lower() not in ("http", "https") or not u.hostname or port == -1 or u.path not in ("", "/") \
            or u.query or u.fragment or u.username is not None:
        raise ConfigError(f"{option} {origin!r}: expected an origin such as http://example.com:3000 "
                          f"(http or https, a host, an optional port, no path)")
    scheme = u.scheme.lower()
    host = f"[{u.hostname}]" if ":" in u.hostname else u.hostname.lower()
    default = {"http": 80, "https": 443}[scheme]
    return f"{scheme}://{host}" + ("" if port in (None, default) else f":{port}")


def same_host_origins(ports: Sequence[int]) -> list[str]:
    """Origins of pages served from this machine's loopback interface on ``ports``."""
    return [f"http://{name}:{p}" for p in dict.fromkeys(ports) for name in LOOPBACK_NAMES]


@dataclass(frozen=True)
class Refusal:
    """Why a handshake is refused: HTTP ``status``, the stats counter ``reason`` and the text
    sent back (``message``: what is wrong and what to do)."""

    status: http.HTTPStatus
    reason: str  # "origin", "host" or "token"
    message: str


@dataclass
class AccessPolicy:
    """The handshake rules of the module doc for one server.

    Args:
        host: the bind address (decides whether the token is required).
        token: the access token (generated when None).
        require_token: require the token on loopback too.
        allow_origins: extra allowed origins (``--allow-origin``; normalised, token required).
        page_ports: ports of same-host pages allowed besides the server's own (the viewer's).
    """

    host: str = "127.0.0.1"
    token: str | None = None
    require_token: bool = False
    allow_origins: Sequence[str] = ()
    page_ports: Sequence[int] = VIEWER_PORTS
    #: The list handed to the library (``serve(origins=...)``); filled by :meth:`bind`.
    origin_list: list[Any] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.token = new_token() if self.token is None else check_token(self.token)
        self.allow_origins = tuple(dict.fromkeys(normalise_origin(o) for o in self.allow_origins))
        self.page_ports = tuple(int(p) for p in self.page_ports)
        self.token_required = token_required(self.host, self.require_token)
        self.bind(None)

    def bind(self, port: int | None) -> list[Any]:
        """Set the server's port (known once bound; port 0 picks one) and return the origins
        list: ``None`` (no Origin header), the same-host pages, then ``allow_origins``. The list
        is updated in place: the library keeps the object it was given."""
        ports = ([port] if port else []) + list(self.page_ports)
        self.origin_list[:] = [None, *same_host_origins(ports), *self.allow_origins]
        return self.origin_list

    def check(self, protocol: Any, request: Any) -> Refusal | None:
        """The module doc's rules for one handshake; ``protocol``: the connection's
        ``websockets.ServerProtocol`` (its ``origins`` is :attr:`origin_list`), ``request``: a
        ``websockets.http11.Request``. Returns None when the request may proceed."""
        try:
            origin = protocol.process_origin(request.headers)
        except InvalidHandshake:  # a foreign origin, or several Origin headers
            return Refusal(http.HTTPStatus.FORBIDDEN, "origin",
                           f"Origin {request.headers.get_all('Origin')!r} is not allowed: this server accepts "
                           f"pages from {', '.join(o for o in self.origin_list if o)}; start it with "
                           f"--allow-origin ORIGIN to add one (such a page must also present the token)\n")
        if not self.token_required and not self._loopback_host_header(request):
            return Refusal(http.HTTPStatus.FORBIDDEN, "host",
                           f"Host {request.headers.get('Host')!r} is not this machine's loopback name: the "
                           f"server listens on {self.host}; connect to 127.0.0.1 or localhost\n")
        given = presented_token(request)
        need = self.token_required or origin in self.allow_origins
        if given is None and not need:
            return None
        if given is None or not secrets.compare_digest(given.encode(), str(self.token).encode()):
            what = "no access token" if given is None else "a wrong access token"
            return Refusal(http.HTTPStatus.UNAUTHORIZED, "token",
                           f"{what}: this server requires the token printed by `wearpose serve` at start-up, "
                           f"as ?token=... in the URL or an 'Authorization: Bearer ...' header "
                           f"(Python client and `wearpose stream replay`: --token)\n")
        return None

    @staticmethod
    def _loopback_host_header(request: Any) -> bool:
        host = request.headers.get("Host", "")
        name = host.rsplit(":", 1)[0] if not host.endswith("]") else host
        return is_loopback_host(name)


def presented_token(request: Any) -> str | None:
    """The token a handshake request carries: its ``token`` query parameter, else an
    ``Authorization: Bearer <token>`` header; None when neither is there."""
    query = urllib.parse.urlsplit(request.path).query
    values = urllib.parse.parse_qs(query).get("token")
    if values:
        return values[0]
    auth = request.headers.get("Authorization", "")
    scheme, _, value = auth.partition(" ")
    return value.strip() if scheme.lower() == "bearer" and value.strip() else None


class TokenBucket:
    """At most ``rate`` events per second on average, bursts up to ``burst`` events.

    Args:
        rate: events/s refilled (> 0).
        burst: bucket size, events (default: one second's worth).
    """

    def __init__(self, rate: float, burst: float | None = None) -> None:
        if rate <= 0:
            raise ConfigError(f"rate limit: expected a positive number of messages per second, got {rate!r}")
        self.rate = float(rate)
        self.burst = float(burst if burst is not None else rate)
        self.level = self.burst
        self.t = time.monotonic()

    def take(self, now: float | None = None) -> bool:
        """Spend one event; False (and nothing spent) when the bucket is empty."""
        now = time.monotonic() if now is None else now
        self.level = min(self.burst, self.level + (now - self.t) * self.rate)
        self.t = now
        if self.level < 1.0:
            return False
        self.level -= 1.0
        return True


class Throttle:
    """Lets through at most ``per_s`` events per second (error replies to one connection: a
    flood of bad messages must not become a flood of answers); counts the rest in
    :attr:`suppressed`."""

    def __init__(self, per_s: float = 10.0) -> None:
        self.bucket = TokenBucket(per_s)
        self.suppressed = 0

    def allow(self) -> bool:
        ok = self.bucket.take()
        self.suppressed += not ok
        return ok


@dataclass(frozen=True)
class Limits:
    """Per-connection limits of the server (each refusal is counted in ``stats()["security"]``).

    Attributes:
        message_bytes: largest message, bytes (``websockets`` ``max_size``; a bigger one closes
            the connection with code 1009: the library cannot skip a message it has not read).
        rate: messages per second per connection (token bucket); messages beyond it are dropped
            unprocessed, counted ``rate_limited`` and reported to the client (at most once a second).
        burst: messages a connection may send at once above ``rate`` (default: one second's worth).
        subscriptions: subject ids one subscription may name (``null`` = every subject counts as 1).
        subscribers: connections subscribed at once, server-wide.
        subjects: subjects one connection may have open at once.
        subscriber_queue: poses queued per subscriber; beyond it the oldest is dropped (the
            overload policy, ``docs/streaming.md``).
        max_lag_s: the estimator overload policy: a frame that has waited longer than this since
            it arrived, with newer frames queued behind it, is shed unestimated (counted ``shed``
            per subject, in the final ``bye`` stats and ``/stats``), so a starved server catches up
            with the newest frames instead of answering seconds late. ``None``: never shed.
    """

    message_bytes: int = MAX_MESSAGE_BYTES
    rate: float = 2000.0
    burst: float | None = None
    subscriptions: int = 16
    subscribers: int = 32
    subjects: int = 16
    subscriber_queue: int = 256
    max_lag_s: float | None = 0.5

    def __post_init__(self) -> None:
        for name in ("message_bytes", "subscriptions", "subscribers", "subjects", "subscriber_queue"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ConfigError(f"Limits.{name}: expected a positive integer, got {v!r}")
        if self.max_lag_s is not None and not self.max_lag_s > 0:
            raise ConfigError(f"Limits.max_lag_s: expected a positive number of seconds or None, got {self.max_lag_s!r}")
        if not self.rate > 0:
            raise ConfigError(f"Limits.rate: expected a positive number of messages per second, got {self.rate!r}")
