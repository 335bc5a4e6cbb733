"""The HTTP server: bad requests get a 4xx and a message, sessions are isolated, capped and time out, a
killed client leaves the server serving, and 64 concurrent sessions earn the verdicts of in-process runs."""

from __future__ import annotations

import http.client
import json
import socket
import subprocess
import sys
import threading
import time

import pytest

pytest.importorskip("starlette", reason="the envs extra is not installed: pip install -e '.[envs]'")
pytest.importorskip("uvicorn", reason="the envs extra is not installed: pip install -e '.[envs]'")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def server(domain):
    """A server in a thread of this process (uvicorn), with a small cap and a short time-out."""
    import uvicorn

    from adaptbench.envs.server import Limits, create_app

    port = _free_port()
    app = create_app(domain, Limits(max_sessions=80, timeout=30.0))
    srv = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="error", access_log=False))
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
        sid = c.reset(seed=0, task="eggs", persona="juan")["session_id"]
        cases = [(b"{not json", 400, "malformed JSON"), (b"[1, 2]", 400, "JSON object"),
                 (json.dumps({"session_id": "nope", "action": "Look for eggs"}).encode(), 404, "unknown or expired"),
                 (json.dumps({"session_id": sid}).encode(), 422, "field 'action'"),
                 (json.dumps({"session_id": sid, "action": "x" * 5000}).encode(), 413, "at most 2000"),
                 (b"{" + b" " * 70_000 + b"}", 413, "request body over"),
                 (json.dumps({"action": "Look for eggs"}).encode(), 422, "missing field 'session_id'")]
        for body, status, message in cases:
            got, answer = _raw(port, "POST", "/step", body)
            assert got == status and message in answer["error"], (body[:40], got, answer)
        for body, message in [({"task": "flambe"}, "unknown task 'flambe'"), ({"seed": -1}, "seed must be >= 0"),
                              ({"seed": "3"}, "must be int"), ({"reward": "money"}, "unknown reward"),
                              ({"max_steps": 10_000}, "max_steps must be in"), ({"colour": 1}, "unknown field")]:
            got, answer = _raw(port, "POST", "/reset", json.dumps(body).encode())
            assert got == 422 and message in answer["error"], (body, answer)
        assert _raw(port, "GET", "/state?session_id=nope")[0] == 404
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
    sid = a.session_id
    a.close()
    with pytest.raises(EnvServerError, match="unknown or expired session"):
        EnvClient(server["url"]).request("POST", "/step", {"session_id": sid, "action": "Look for eggs"})
    b.close()


def test_cap_and_time_out(domain):
    from adaptbench.envs.server import BadRequest, Handlers, Limits

    h = Handlers(domain, Limits(max_sessions=2, timeout=0.2))
    s1 = h.reset({"seed": 0})["session_id"]
    h.reset({"seed": 1})
    with pytest.raises(BadRequest) as exc:
        h.reset({"seed": 2})
    assert exc.value.status == 429 and "maximum of 2 sessions" in exc.value.message
    time.sleep(0.3)
    with pytest.raises(BadRequest) as exc:
        h.step({"session_id": s1, "action": "Look for eggs"})
    assert exc.value.status == 404
    h.reset({"seed": 3})  # the idle ones timed out: room again
    assert len(h.sessions) == 1 and h.sessions.expired == 2


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
