"""A client for `adapt serve-env`'s HTTP routes (standard library only: one kept-alive HTTP connection per
client). The server makes the session's id and secret at reset; the client sends both with every call.
OpenEnv's own clients (`openenv.core.GenericEnvClient`) speak to the same server over `/ws`.

    with EnvClient("http://127.0.0.1:8000") as env:
        out = env.reset(seed=3, task="eggs", persona="juan")
        print(out["observation"]["text"])
        out = env.step("Look for eggs")          # observation, reward, done, terminated, truncated, info
        env.state()                               # step count, done, verdicts once over

A 4xx or 5xx answer raises `EnvServerError` with the server's status and message.
"""

from __future__ import annotations

import http.client
import json
from urllib.parse import urlsplit


class EnvServerError(Exception):
    """The server refused a request: `status` and the server's `message`."""

    def __init__(self, status: int, message: str):
        super().__init__(f"HTTP {status}: {message}")
        self.status, self.message = status, message


class EnvClient:
    """One session on an ADAPT environment server (`reset` opens it, `close` ends it)."""

    def __init__(self, base_url: str = "http://127.0.0.1:8000", timeout: float = 60.0):
        url = urlsplit(base_url)
        if url.scheme != "http" or not url.hostname:
            raise ValueError(f"expected an http://HOST:PORT address, got '{base_url}'")
        self.host, self.port, self.timeout = url.hostname, url.port or 80, timeout
        self.session_id: str | None = None
        self.secret: str | None = None
        self._conn: http.client.HTTPConnection | None = None

    def request(self, method: str, path: str, body: dict | None = None) -> dict:
        """Send one request and return the decoded JSON answer (EnvServerError on 4xx/5xx). Reconnects
        once if the kept-alive connection was closed."""
        data = None if body is None else json.dumps(body).encode()
        for attempt in (0, 1):
            conn = self._connection()
            try:
                conn.request(method, path, body=data, headers={"Content-Type": "application/json"})
                resp = conn.getresponse()
                raw = resp.read()
                break
            except (http.client.RemoteDisconnected, ConnectionResetError, BrokenPipeError):
                self._drop()
                if attempt:
                    raise
        out = json.loads(raw) if raw else {}
        if resp.status >= 400:
            raise EnvServerError(resp.status, out.get("error", raw.decode(errors="replace")) if isinstance(out, dict)
                                 else str(out))
        return out

    def reset(self, **options) -> dict:
        """Open a new session for this client (its previous one, if any, is closed by the same request):
        seed, task, persona, reward, max_steps, prior."""
        out = self.request("POST", "/reset", {**options, **self._credentials(required=False)})
        self.session_id, self.secret = out["session_id"], out["secret"]
        return out

    def step(self, action: str) -> dict:
        """Take one action in this client's session."""
        return self.request("POST", "/step", {**self._credentials(), "action": {"text": action}})

    def state(self) -> dict:
        """The session's state (verdicts once the episode is over)."""
        return self.request("POST", "/state", self._credentials())

    def health(self) -> dict:
        """The server's health line (open sessions)."""
        return self.request("GET", "/health")

    def close(self) -> None:
        """End the session on the server (one that already expired is fine) and the connection."""
        try:
            if self.session_id is not None:
                self.request("POST", "/close", self._credentials())
        except EnvServerError as exc:
            if exc.status != 404:
                raise
        finally:
            self.session_id = self.secret = None
            self._drop()

    def __enter__(self) -> EnvClient:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _credentials(self, required: bool = True) -> dict:
        if self.session_id is None:
            if required:
                raise RuntimeError("call reset() first")
            return {}
        return {"session_id": self.session_id, "secret": self.secret}

    def _connection(self) -> http.client.HTTPConnection:
        if self._conn is None:
            self._conn = http.client.HTTPConnection(self.host, self.port, timeout=self.timeout)
        return self._conn

    def _drop(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None
