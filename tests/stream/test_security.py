"""The access rules of the streaming server (:mod:`wearpose.stream.security`), without a
socket: Origin allow-list, Host check, access token, token-required policy, token bucket."""

from __future__ import annotations

import pytest
from websockets.datastructures import Headers
from websockets.http11 import Request
from websockets.server import ServerProtocol

from tests.stream.conftest import EchoEstimator
from wearpose.errors import ConfigError
from wearpose.stream import StreamServer
from wearpose.stream.security import (
    AccessPolicy,
    Limits,
    TokenBucket,
    check_token,
    is_loopback_host,
    normalise_origin,
    token_required,
)

EVIL = "http://evil.example.com"


def _request(path: str = "/", **headers: str) -> Request:
    return Request(path, Headers({"Host": "127.0.0.1:8765", **headers}))


def _check(policy: AccessPolicy, request: Request) -> str | None:
    """The refusal reason of ``policy`` for ``request`` (None: accepted)."""
    protocol = ServerProtocol(origins=policy.origin_list)
    refusal = policy.check(protocol, request)
    return None if refusal is None else f"{refusal.status.value} {refusal.reason}"


def test_token_is_required_on_any_non_loopback_bind() -> None:
    for host in ("127.0.0.1", "127.0.0.2", "localhost", "::1", "[::1]"):
        assert is_loopback_host(host) and not token_required(host), host
        assert token_required(host, require_token=True), host
    for host in ("0.0.0.0", "::", "", "192.168.1.20", "10.0.0.1", "wearpose.lan", "example.com"):
        assert not is_loopback_host(host) and token_required(host), host
    # the server's own configuration, without binding anything
    srv = StreamServer(EchoEstimator, host="0.0.0.0", port=0)
    assert srv.token_required and len(srv.token) >= 43
    assert not StreamServer(EchoEstimator, port=0).token_required
    # and the rule it applies: on a non-loopback bind, no token -> 401 even without an Origin
    policy = AccessPolicy("0.0.0.0", token="t" * 20)
    lan = {"Host": "192.168.1.20:8765"}
    assert _check(policy, Request("/", Headers(lan))) == "401 token"
    assert _check(policy, Request("/?token=" + "t" * 20, Headers(lan))) is None
    assert _check(policy, Request("/", Headers({**lan, "Authorization": "Bearer " + "t" * 20}))) is None
    assert _check(policy, Request("/?token=" + "u" * 20, Headers(lan))) == "401 token"


def test_origin_and_token_rules() -> None:
    tok = "s3cret-token-0123456789"
    policy = AccessPolicy("127.0.0.1", token=tok, allow_origins=["HTTP://Dashboard.example:3000/"])
    policy.bind(8765)
    assert _check(policy, _request()) is None  # no Origin: a non-browser client
    assert _check(policy, _request(Origin="http://127.0.0.1:8765")) is None  # same-host page, server port
    assert _check(policy, _request(Origin="http://localhost:8080")) is None  # same-host page, viewer port
    # a foreign page: refused with or without the token
    assert _check(policy, _request(Origin=EVIL)) == "403 origin"
    assert _check(policy, _request("/?token=" + tok, Origin=EVIL)) == "403 origin"
    assert _check(policy, _request(Origin="http://127.0.0.1:9999")) == "403 origin"  # another local port
    # an allowed cross-site origin needs the token too
    assert _check(policy, _request(Origin="http://dashboard.example:3000")) == "401 token"
    assert _check(policy, _request("/?token=" + tok, Origin="http://dashboard.example:3000")) is None
    # a wrong token is refused even where none is needed
    assert _check(policy, _request("/?token=wrong-token-0123456789")) == "401 token"
    # DNS rebinding: a loopback socket reached under another name
    assert _check(policy, Request("/", Headers({"Host": "evil.example.com:8765"}))) == "403 host"
    # --require-token: same-host pages and plain clients need it too
    strict = AccessPolicy("127.0.0.1", token=tok, require_token=True)
    assert _check(strict, _request()) == "401 token" and _check(strict, _request("/?token=" + tok)) is None


def test_bad_tokens_and_origins_name_the_option_and_the_fix() -> None:
    with pytest.raises(ConfigError, match="--token: expected at least 16 characters"):
        check_token("short")
    with pytest.raises(ConfigError, match="--token"):
        check_token("has spaces in it, sixteen+")
    with pytest.raises(ConfigError, match=r"--allow-origin 'example.com': expected an origin such as http://"):
        normalise_origin("example.com")
    with pytest.raises(ConfigError, match="no path"):
        normalise_origin("http://example.com/app")
    assert normalise_origin("HTTPS://Example.COM:443/") == "https://example.com"


def test_token_bucket_rate_and_burst() -> None:
    b = TokenBucket(10.0, burst=5)
    t0 = b.t
    assert sum(b.take(t0) for _ in range(20)) == 5  # the burst, then empty
    assert sum(b.take(t0 + 1.0) for _ in range(20)) == 5  # refilled to the burst, not beyond
    with pytest.raises(ConfigError, match="positive number of messages per second"):
        TokenBucket(0)
    with pytest.raises(ConfigError, match="Limits.subscriptions: expected a positive integer"):
        Limits(subscriptions=0)
