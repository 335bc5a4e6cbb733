"""The HTTP server: bad requests get a 4xx and a message, sessions are isolated, belong to their client
(server-made id and secret), are capped and time out, a killed client leaves the server serving, and 64
concurrent sessions earn the verdicts of in-process runs. The hostile cases against the whole process are
in tests/faults/test_server_hostile.py; OpenEnv's own client in test_openenv_client.py."""

from __future__ import annotations

import http.client
import json
import subprocess
import sys
import threading
import time

import pytest

from ..procs import free_port

pytest.importorskip("starlette", reason="the envs extra is not installed: pip install -e '.[envs]'")
pytest.importorskip("uvicorn", reason="the envs extra is not installed: pip install -e '.[envs]'")


@pytest.fixture(scope="module")
def server(domain):
    """A server in a thread of this process (uvicorn), with a small cap and a short time-out."""
    import uvicorn

    from adaptbench.envs.server import Limits, create_app, uvicorn_config

    port = free_port()
    limits = Limits(max_sessions=80, timeout=30.0)
    app = create_app(domain, limits)
    srv = uvicorn.Server(uvicorn_config(app, "127.0.0.1", port, limits, "error"))
    thread = threading.Thread(target=srv.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 20
    while not srv.started and time.monotonic() < deadline:
        time.sleep(0.05)
    yield {"url": f"http://127.0.0.1:{port}", "port": port, "app": app}
    srv.should_exit = True
    thread.join(timeout=10)


def _raw(port: int, method: str, path: str, body: bytes | None = None) -> tuple:
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    conn.request(method, path, body=body, headers={"Content-Type": "application/json"})
    r = conn.getresponse()
    data = r.read()
    conn.close()
    return r.status, json.loads(data) if data.startswith(b"{") else data


def _healthy(server) -> bool:
    return _raw(server["port"], "GET", "/health")[1]["status"] == "healthy"


def test_bad_requests_are_4xx_with_a_message(server):
    from adaptbench.envs.client import EnvClient

    port = server["port"]
    with EnvClient(server["url"]) as c:
        c.reset(seed=0, task="eggs", persona="juan")
        sid, secret = c.session_id, c.secret
        cases = [(b"{not json", 400, "malformed JSON"), (b"[1, 2]", 400, "JSON object"),
                 (json.dumps({"session_id": "nope", "secret": "x", "action": "Look for eggs"}).encode(), 404,
                  "unknown or expired"),
                 (json.dumps({"session_id": sid, "secret": secret}).encode(), 422, "field 'action'"),
                 (json.dumps({"session_id": sid, "secret": secret, "action": "x" * 5000}).encode(), 413,
                  "at most 2000"),
                 (b"{" + b" " * 70_000 + b"}", 413, "a body is at most"),
                 (json.dumps({"action": "Look for eggs"}).encode(), 422, "missing field 'session_id'"),
                 (json.dumps({"session_id": sid, "action": "Look for eggs"}).encode(), 422, "missing field 'secret'"),
                 (json.dumps({"session_id": sid, "secret": "guess", "action": "Look"}).encode(), 403, "wrong secret")]
        for body, status, message in cases:
            got, answer = _raw(port, "POST", "/step", body)
            assert got == status and message in answer["error"], (body[:40], got, answer)
        for body, message in [({"task": "flambe"}, "unknown task 'flambe'"), ({"seed": -1}, "seed must be in 0.."),
                              ({"seed": "3"}, "must be an integer"), ({"reward": "money"}, "unknown reward"),
                              ({"max_steps": 10_000}, "max_steps must be in"), ({"colour": 1}, "unknown field")]:
            got, answer = _raw(port, "POST", "/reset", json.dumps(body).encode())
            assert got == 422 and message in answer["error"], (body, answer)
        assert _raw(port, "GET", "/state?session_id=nope&secret=x")[0] == 404
        assert c.state()["step_count"] == 0
        assert c.step("Look for eggs")["info"]["ok"]  # the session is untouched by all of that
    assert _healthy(server)


def test_sessions_are_isolated_and_closed(server):
    from adaptbench.envs.client import EnvClient, EnvServerError

    a, b = EnvClient(server["url"]), EnvClient(server["url"])
    a.reset(seed=0, task="eggs", persona="juan")
    b.reset(seed=1, task="toast_coffee", persona="ron", reward="progress")
    a.step("Look for eggs")
    assert a.state()["step_count"] == 1 and b.state()["step_count"] == 0
    assert b.state()["task"] == "toast_coffee"
    sid, secret = a.session_id, a.secret
    a.close()
    with pytest.raises(EnvServerError, match="unknown or expired session"):
        EnvClient(server["url"]).request("POST", "/step", {"session_id": sid, "secret": secret,
                                                           "action": "Look for eggs"})
    b.close()


def test_sessions_belong_to_their_client(server):
    """The server makes ids (unguessable) and secrets; a reset naming another's session, or an id the client
    chose, takes nothing over; a reset naming the client's own session replaces it with a new one."""
    from adaptbench.envs.client import EnvClient, EnvServerError

    port = server["port"]
    a, b = EnvClient(server["url"]), EnvClient(server["url"])
    a.reset(seed=0, task="eggs", persona="juan")
    a.step("Look for eggs")
    b.reset(seed=1)
    assert len({a.session_id, b.session_id}) == 2 and len(a.session_id) >= 20 and len(a.secret) >= 30
    for body, status, message in [({"session_id": a.session_id}, 422, "missing field 'secret'"),
                                  ({"session_id": a.session_id, "secret": b.secret}, 403, "wrong secret"),
                                  ({"episode_id": a.session_id}, 422, "the server makes session ids"),
                                  ({"session_id": "mine", "secret": "mine"}, 404, "unknown or expired")]:
        got, answer = _raw(port, "POST", "/reset", json.dumps(body).encode())
        assert (got, message in answer["error"]) == (status, True), (body, answer)
    for method, path in [("GET", f"/state?session_id={a.session_id}"), ("POST", "/close"),
                         ("DELETE", f"/sessions/{a.session_id}?secret={b.secret}")]:
        body = json.dumps({"session_id": a.session_id, "secret": b.secret}).encode() if method == "POST" else None
        assert _raw(port, method, path, body)[0] in (403, 422)
    assert a.state()["step_count"] == 1  # a's episode untouched by all of that
    old = a.session_id
    a.reset(seed=2)  # the client's own session: closed, a new one opened
    assert a.session_id != old and a.state()["step_count"] == 0
    assert _raw(port, "GET", f"/state?session_id={old}&secret=x")[0] == 404
    assert _raw(port, "DELETE", f"/sessions/{b.session_id}?secret={b.secret}") == (200, {"closed": True})
    with pytest.raises(EnvServerError, match="unknown or expired"):
        b.state()
    a.close()


def test_cap_and_time_out(domain):
    from adaptbench.envs.server import BadRequest, Handlers, Limits

    h = Handlers(domain, Limits(max_sessions=2, timeout=0.2))
    first = h.reset({"seed": 0})
    h.reset({"seed": 1})
    with pytest.raises(BadRequest) as exc:
        h.reset({"seed": 2})
    assert exc.value.status == 429 and "maximum of 2 sessions" in exc.value.message
    time.sleep(0.3)
    with pytest.raises(BadRequest) as exc:
        h.step({"session_id": first["session_id"], "secret": first["secret"], "action": "Look for eggs"})
    assert exc.value.status == 404
    h.reset({"seed": 3})  # the idle ones timed out: room again
    assert len(h.sessions) == 1 and h.sessions.expired == 2


def test_closing_an_expired_session_is_quiet(server):
    from adaptbench.envs.client import EnvClient

    with EnvClient(server["url"]) as c:
        c.reset(seed=0)
        server["app"].state.handlers.sessions.drop(c.session_id)  # as the reaper would
    assert c.session_id is None


CLIENT = """
import sys, time
from adaptbench.envs.client import EnvClient
c = EnvClient(sys.argv[1])
c.reset(seed=0, task="eggs", persona="juan")
print("ready", flush=True)
while True:
    c.step("Look for eggs"); c.step("Look for milk")
"""


def test_client_killed_mid_episode(server):
    from adaptbench.envs.client import EnvClient

    proc = subprocess.Popen([sys.executable, "-c", CLIENT, server["url"]], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(0.3)
    finally:
        proc.kill()
        proc.wait(timeout=10)
    with EnvClient(server["url"]) as c:
        c.reset(seed=0, task="eggs", persona="juan")
        assert c.step("Look for eggs")["info"]["ok"]
    assert _healthy(server)


def test_64_concurrent_sessions_match_in_process(server, oracle_mix):
    from adaptbench.envs.client import EnvClient

    results, errors = {}, []

    def play(k: int):
        ep = oracle_mix[k % len(oracle_mix)]
        try:
            with EnvClient(server["url"]) as c:
                c.reset(seed=ep["seed"], task=ep["task"], persona=ep["persona"])
                out = {}
                for a in ep["actions"]:
                    out = c.step(a)
                results[k] = (out["done"], out["info"]["verdicts"], c.state()["verdicts"])
        except Exception as exc:  # noqa: BLE001 - collected and asserted on below
            errors.append(f"{k}: {exc}")

    threads = [threading.Thread(target=play, args=(k,)) for k in range(64)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert errors == [] and len(results) == 64
    for k, (done, verdicts, state_verdicts) in results.items():
        expected = oracle_mix[k % len(oracle_mix)]["verdicts"]
        assert done and verdicts == expected == state_verdicts, k
    assert _healthy(server)


def test_serve_env_command_refuses_a_busy_port_and_a_bad_one(server, capsys):
    from adaptbench.cli.main import main
    from tests.conftest import SPEC

    assert main(["serve-env", "--spec", str(SPEC), "--port", str(server["port"])]) == 1
    assert f"adapt: cannot listen on 127.0.0.1:{server['port']}" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["serve-env", "--port", "70000"])
    assert exc.value.code == 2
    assert "port 70000 is out of range" in capsys.readouterr().err
