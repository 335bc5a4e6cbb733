"""A hostile client against the whole `adapt serve-env` process (a subprocess on a free port, request
time-out 1 s): every bad request is a 4xx with a JSON message and changes nothing (no step counted, no
session opened or replaced); a reset never takes over another's session; idle, trickling and lying
connections are closed after the documented time-out while /health stays fast."""

from __future__ import annotations

import contextlib
import json
import socket
import time

import pytest

pytest.importorskip("starlette", reason="the envs extra is not installed: pip install -e '.[envs]'")
pytest.importorskip("uvicorn", reason="the envs extra is not installed: pip install -e '.[envs]'")

from tests.envs.serverproc import request, serve_env  # noqa: E402

REQUEST_TIMEOUT = 1


@pytest.fixture(scope="module")
def port():
    with serve_env("--request-timeout", str(REQUEST_TIMEOUT), "--max-sessions", "300") as p:
        yield p


@pytest.fixture
def episode(port):
    """A fresh session: (session_id, secret)."""
    status, out = request(port, "POST", "/reset", {"seed": 0, "task": "eggs", "persona": "juan"})
    assert status == 200
    yield out["session_id"], out["secret"]
    request(port, "POST", "/close", {"session_id": out["session_id"], "secret": out["secret"]})


def _refused(answer: tuple, status: int | None = None, message: str = "") -> None:
    got, body = answer
    assert 400 <= got < 500 and (status is None or got == status), answer
    assert isinstance(body, dict) and isinstance(body.get("error"), str) and message in body["error"], answer


def _steps(port: int, sid: str, secret: str) -> int:
    status, out = request(port, "POST", "/state", {"session_id": sid, "secret": secret})
    assert status == 200, out
    return out["step_count"]


def _opened(port: int) -> tuple:
    h = request(port, "GET", "/health")[1]
    return h["opened"], h["sessions"]


STEP_BODIES = [  # (name, body as bytes with {sid} and {secret} to fill, status, message)
    ("lone surrogate in the action", '{"session_id": "{sid}", "secret": "{secret}", "action": "Look for \\ud800"}',
     400, "lone surrogate"),
    ("lone surrogate in {text}", '{"session_id": "{sid}", "secret": "{secret}", "action": {"text": "\\udfff"}}',
     400, "lone surrogate"),
    ("surrogate in a key", '{"session_id": "{sid}", "secret": "{secret}", "action": "Look", "\\ud800": 1}',
     400, "lone surrogate"),
    ("invalid UTF-8", b'{"session_id": "{sid}", "secret": "{secret}", "action": "Look for \xff\xfe"}',
     400, "not valid UTF-8"),
    ("UTF-16", '{"session_id": "{sid}"}'.encode("utf-16"), 400, "not valid UTF-8"),
    ("deep nesting (RecursionError)", "[" * 30_000, 400, "nested too deep"),
    ("nesting past the limit", '{"session_id": "{sid}", "secret": "{secret}", "action": "Look", "x": '
     + "[" * 40 + "]" * 40 + "}", 400, "nested too deep"),
    ("null session_id", '{"session_id": null, "secret": "{secret}", "action": "Look"}', 422, "not null"),
    ("null secret", '{"session_id": "{sid}", "secret": null, "action": "Look"}', 422, "not null"),
    ("null action", '{"session_id": "{sid}", "secret": "{secret}", "action": null}', 422, "not null"),
    ("null text", '{"session_id": "{sid}", "secret": "{secret}", "action": {"text": null}}', 422, "not null"),
    ("number action", '{"session_id": "{sid}", "secret": "{secret}", "action": 5}', 422, "not integer"),
    ("number session_id", '{"session_id": 5, "secret": "{secret}", "action": "Look"}', 422, "must be a string"),
    ("array body", "[]", 400, "JSON object"),
    ("string body", '"Look for eggs"', 400, "JSON object"),
    ("wrong secret", '{"session_id": "{sid}", "secret": "guess", "action": "Look for eggs"}', 403, "wrong secret"),
    ("huge number", '{"session_id": "{sid}", "secret": "{secret}", "action": ' + "9" * 5000 + "}", 400, "malformed"),
]


@pytest.mark.parametrize("name,body,status,message", STEP_BODIES, ids=[c[0] for c in STEP_BODIES])
def test_a_bad_step_is_refused_and_counts_no_step(port, episode, name, body, status, message):
    sid, secret = episode
    raw = body if isinstance(body, bytes) else body.encode()
    raw = raw.replace(b"{sid}", sid.encode()).replace(b"{secret}", secret.encode())
    _refused(request(port, "POST", "/step", raw), status, message)
    assert _steps(port, sid, secret) == 0
    ok = request(port, "POST", "/step", {"session_id": sid, "secret": secret, "action": "Look for eggs"})
    assert ok[0] == 200 and _steps(port, sid, secret) == 1  # the session goes on


RESET_BODIES = [
    ("surrogate task", '{"task": "\\ud800"}', 400, "lone surrogate"),
    ("surrogate persona", '{"persona": "ju\\udc00an"}', 400, "lone surrogate"),
    ("surrogate prior", '{"prior": ["\\ud800"]}', 400, "lone surrogate"),
    ("invalid UTF-8", b'{"task": "\xc3\x28"}', 400, "not valid UTF-8"),
    ("deep nesting", '{"prior": ' + "[" * 30_000 + "}", 400, "nested too deep"),
    ("null seed", '{"seed": null}', 422, "not null"),
    ("null max_steps", '{"max_steps": null}', 422, "not null"),
    ("null reward", '{"reward": null}', 422, "not null"),
    ("null prior", '{"prior": null}', 422, "field 'prior'"),
    ("float seed", '{"seed": 1.5}', 422, "not number"),
    ("boolean seed", '{"seed": true}', 422, "not boolean"),
    ("huge seed", '{"seed": ' + "9" * 100 + "}", 422, "seed must be in"),
    ("array max_steps", '{"max_steps": []}', 422, "not array"),
    ("object task", '{"task": {}}', 422, "not object"),
    ("client-chosen episode_id", '{"episode_id": "mine"}', 422, "the server makes session ids"),
    ("unknown session_id", '{"session_id": "mine", "secret": "mine"}', 404, "unknown or expired"),
]


@pytest.mark.parametrize("name,body,status,message", RESET_BODIES, ids=[c[0] for c in RESET_BODIES])
def test_a_bad_reset_is_refused_and_opens_nothing(port, name, body, status, message):
    before = _opened(port)
    _refused(request(port, "POST", "/reset", body if isinstance(body, bytes) else body.encode()), status, message)
    assert _opened(port) == before


@pytest.mark.parametrize("method,path,body", [
    ("POST", "/state", '{"session_id": "\\ud800", "secret": "x"}'),
    ("GET", "/state?session_id=%ED%A0%80&secret=x", None),
    ("GET", "/state?session_id=%ff%fe&secret=%00", None),
    ("POST", "/close", '{"session_id": "\\ud800", "secret": "\\udfff"}'),
    ("DELETE", "/sessions/%ED%A0%80?secret=x", None),
    ("GET", "/state", None),
], ids=["state body", "state query surrogate bytes", "state query bad bytes", "close", "delete", "no id"])
def test_bad_session_ids_are_refused_with_json(port, method, path, body):
    _refused(request(port, method, path, body.encode() if body else None))


def test_a_reset_never_takes_over_another_session(port, episode):
    sid, secret = episode
    request(port, "POST", "/step", {"session_id": sid, "secret": secret, "action": "Look for eggs"})
    before = _opened(port)
    for body, status in [({"session_id": sid}, 422), ({"session_id": sid, "secret": "guess"}, 403),
                         ({"session_id": sid, "secret": None}, 422), ({"episode_id": sid}, 422)]:
        _refused(request(port, "POST", "/reset", body), status)
    _refused(request(port, "POST", "/close", {"session_id": sid, "secret": "guess"}), 403)
    _refused(request(port, "DELETE", f"/sessions/{sid}?secret=guess"), 403)
    assert _opened(port) == before and _steps(port, sid, secret) == 1


def _closed(sock: socket.socket, got: dict) -> bool:
    """Whether the server closed `sock` (reading what it sent into got[sock])."""
    try:
        data = sock.recv(65536)
    except BlockingIOError:
        return False
    except OSError:
        return True
    if data:
        got[sock] = got.get(sock, b"") + data
        return False
    return True


def _open_stalled(port: int, n: int) -> dict:
    """n connections, each {socket: kind}: idle (nothing sent), trickle (a request line sent later, a byte
    at a time), lying (headers promise a 1000-byte body, 5 bytes follow) or slow_body (the same headers,
    then the body a byte at a time)."""
    kinds, socks = ["idle", "trickle", "lying", "slow_body"], {}
    for i in range(n):
        s = socket.create_connection(("127.0.0.1", port), timeout=5)
        kind = kinds[i % len(kinds)]
        if kind in ("lying", "slow_body"):
            s.sendall(b"POST /step HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
                      b"Content-Length: 1000\r\n\r\n{\"a\":")
        s.setblocking(False)
        socks[s] = kind
        OPENED[s] = time.monotonic()
    return socks


OPENED: dict = {}  # socket -> when it was opened


TRICKLE = b"POST /step HTTP/1.1\r\nHost: localhost\r\nContent-Type: application/json\r\n"


def _watch(port: int, socks: dict, seconds: float) -> tuple:
    """Trickle a byte into each trickling socket every 0.2 s, time /health meanwhile, until every socket is
    closed or `seconds` pass: (seconds after its opening each socket closed, what each received, /health times)."""
    start, closed_at, got, health, n = time.monotonic(), {}, {}, [], 0
    while len(closed_at) < len(socks) and time.monotonic() - start < seconds:
        for s in (s for s in socks if s not in closed_at):
            if socks[s] in ("trickle", "slow_body"):
                with contextlib.suppress(OSError):
                    s.send(TRICKLE[n % len(TRICKLE):n % len(TRICKLE) + 1] if socks[s] == "trickle" else b" ")
            if _closed(s, got):
                closed_at[s] = time.monotonic() - OPENED[s]
        n += 1
        t = time.perf_counter()
        assert request(port, "GET", "/health", timeout=5)[0] == 200
        health.append(time.perf_counter() - t)
        time.sleep(0.2)
    return closed_at, got, health


def test_idle_trickling_and_lying_connections_are_closed(port):
    """200 connections that never finish a request: idle (nothing sent), trickling (a byte of a request
    line every 0.2 s), lying (Content-Length 1000, 5 bytes sent) and slow bodies (Content-Length 1000, a
    byte every 0.2 s). All are closed within the request time-out plus slack, those that sent headers
    after a JSON 408; /health answers fast throughout."""
    socks = _open_stalled(port, 200)
    try:
        closed_at, got, health = _watch(port, socks, REQUEST_TIMEOUT + 8)
        still = [kind for s, kind in socks.items() if s not in closed_at]
        assert not still, f"{len(still)} of 200 still open: {sorted(set(still))}"
        assert min(closed_at.values()) >= REQUEST_TIMEOUT * 0.8  # closed by the time-out, not at once
        for s in (s for s, kind in socks.items() if kind in ("lying", "slow_body")):
            head, _, body = got.get(s, b"").partition(b"\r\n\r\n")
            assert head.startswith(b"HTTP/1.1 408") and b"did not arrive within" in body, got.get(s)
        assert max(health) < 1.0, f"/health took up to {max(health):.3f} s"
        print(f"200 stalled connections closed after {min(closed_at.values()):.2f}-{max(closed_at.values()):.2f} s; "
              f"/health max {1e3 * max(health):.1f} ms over {len(health)} requests")
    finally:
        for s in socks:
            s.close()


def test_an_idle_websocket_is_closed_after_the_session_time_out():
    """A /ws connection silent longer than the session time-out (1 s here) gets a close frame (1001) and
    its session is gone; a connection that keeps talking is not affected."""
    import asyncio

    pytest.importorskip("websockets", reason="the envs extra is not installed: pip install -e '.[envs]'")
    from websockets.asyncio.client import connect
    from websockets.exceptions import ConnectionClosed

    async def main(port: int):
        async with connect(f"ws://127.0.0.1:{port}/ws") as idle, connect(f"ws://127.0.0.1:{port}/ws") as busy:
            for ws in (idle, busy):
                await ws.send(json.dumps({"type": "reset", "data": {"seed": 0}}))
                assert json.loads(await ws.recv())["type"] == "observation"
            for _ in range(8):  # 2 s of steps on `busy`
                await busy.send(json.dumps({"type": "step", "data": {"text": "Look for eggs"}}))
                assert json.loads(await busy.recv())["type"] == "observation"
                await asyncio.sleep(0.25)
            with pytest.raises(ConnectionClosed) as exc:
                await asyncio.wait_for(idle.recv(), 5)
            assert exc.value.rcvd.code == 1001 and "idle for 1 s" in exc.value.rcvd.reason
            return request(port, "GET", "/health")[1]["sessions"]

    with serve_env("--timeout", "1") as port:
        assert asyncio.run(main(port)) == 1  # only the busy connection's session is left


@pytest.mark.parametrize("raw", [
    b"GARBAGE\r\n\r\n",
    b"POST /step HTTP/1.1\r\nHost: x\r\nContent-Length: ten\r\n\r\n{}",
    b"POST /step HTTP/1.1\r\nHost: x\r\nno colon here\r\n\r\n",
    b"POST /step HTTP/1.1\r\nHost: x\r\nContent-Length: 2\r\nContent-Length: 3\r\n\r\n{}",
], ids=["request line", "Content-Length not a number", "header without colon", "two Content-Lengths"])
def test_unparsable_http_is_a_json_400(port, raw):
    with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
        s.sendall(raw)
        data = b""
        while chunk := s.recv(65536):
            data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    assert head.startswith(b"HTTP/1.1 400") and b"application/json" in head, data
    assert "error" in json.loads(body)
    assert request(port, "GET", "/health")[0] == 200


@pytest.mark.parametrize("method,path,status,message", [
    ("GET", "/nowhere", 404, "no route '/nowhere'"), ("GET", "/step", 405, "GET is not allowed on /step"),
    ("PUT", "/reset", 405, "PUT is not allowed"), ("GET", "/ws", 404, "routes: "),
])
def test_unknown_routes_and_methods_are_json(port, method, path, status, message):
    _refused(request(port, method, path), status, message)
