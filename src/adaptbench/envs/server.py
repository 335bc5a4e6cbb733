"""ADAPT served to many clients at once, each session its own episode (seed, persona, task): OpenEnv's
WebSocket protocol at `/ws` (what `openenv-core`'s `GenericEnvClient` speaks) beside HTTP routes. A
standard ASGI app (Starlette), run by uvicorn (`adapt serve-env --port 8000`).

HTTP (a session is named by its id and its secret, both made by the server at reset):

    POST /reset   {"seed": 3, "task": "eggs", "persona": "juan", "reward": "final", "max_steps": 50}
                  -> {"session_id": "...", "secret": "...", "observation": {"text": ..., "info": {...}},
                      "reward": null, "done": false}
    POST /step    {"session_id": "...", "secret": "...", "action": {"text": "Look for eggs"}}
                  -> {"observation": {"text": ...}, "reward": 0.0, "done": false, "terminated": false,
                      "truncated": false, "info": {"step": 1, "ok": true, "action": "look_for", ...}}
    GET  /state?session_id=...&secret=...   (or POST)  -> step count, task, done, verdicts once over
    POST /close   {"session_id": "...", "secret": "..."}      (DELETE /sessions/{id}?secret=... too)
    GET  /health, GET /info      (open sessions; task and persona ids, limits)

WebSocket `/ws` (OpenEnv's messages): {"type": "reset", "data": {...reset fields}}, {"type": "step",
"data": {"text": "Look for eggs"}}, {"type": "state"}, {"type": "close"}; answers {"type": "observation",
"data": {"observation": {"text", "info", "terminated", "truncated"}, "reward", "done"}}, {"type": "state",
"data": {...}}, {"type": "error", "data": {"message", "code", "status"}}. The connection owns its session:
a reset there replaces only that connection's episode, and closing the connection closes it.

Every bad request is refused before anything changes (`envs.wire`): a 4xx with {"error": message}
(on /ws an error message, the connection stays open). Sessions idle longer than the time-out are dropped;
connections that do not finish a request in time are closed (`envs.connections`).

Steps run on the event loop itself (an episode step takes well under a millisecond, and a single thread
needs no locks): requests of different sessions interleave, each session's requests are served in order.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import secrets
import time
from dataclasses import dataclass

from ..compiler.model import CompiledDomain
from ..runtime.env import MAX_STEPS
from .session import MAX_ACTION_CHARS, REWARDS, Session
from .wire import MAX_BODY, BadRequest, action_text, field, parse_body, render

__all__ = ["MAX_BODY", "BadRequest", "Handlers", "Limits", "Sessions", "create_app", "serve"]

MAX_SEED = 2**63 - 1
ROUTES = ("POST /reset, POST /step, GET|POST /state, POST /close, DELETE /sessions/{id}, GET /health, GET /info, "
          "WebSocket /ws")
RESET_FIELDS = {"seed", "task", "persona", "reward", "max_steps", "prior", "session_id", "secret"}


@dataclass
class Limits:
    """Server limits: concurrent sessions, idle session time-out (s), largest step limit a client may ask,
    and the seconds a connection has to send each request's headers, and then its body."""

    max_sessions: int = 1024
    timeout: float = 600.0
    max_steps: int = 200
    request_timeout: float = 10.0


class Sessions:
    """The open sessions by id, each with its secret and last use; idle ones are dropped by `reap`."""

    def __init__(self, domain: CompiledDomain, limits: Limits):
        self.domain, self.limits = domain, limits
        self._open: dict = {}  # id -> [Session, last use, secret]
        self.opened = self.expired = 0

    def __len__(self) -> int:
        return len(self._open)

    def reap(self, now: float | None = None) -> int:
        """Drop sessions idle longer than the time-out; returns how many."""
        now = time.monotonic() if now is None else now
        old = [sid for sid, (_, used, _) in self._open.items() if now - used > self.limits.timeout]
        for sid in old:
            del self._open[sid]
        self.expired += len(old)
        return len(old)

    def open(self, args: dict, replacing: bool = False) -> tuple:
        """A new session from checked reset arguments: (id, secret, Session); the server makes both.
        `replacing`: the caller closes one of its own next, so the cap leaves room for one more."""
        self.reap()
        if len(self._open) - replacing >= self.limits.max_sessions:
            raise BadRequest(429, f"the server holds its maximum of {self.limits.max_sessions} sessions; "
                                  "close one or wait for idle ones to time out", "CAPACITY_REACHED")
        try:
            session = Session.open(self.domain, **args)
        except (KeyError, ValueError) as exc:
            raise BadRequest(422, str(exc).strip("'\"")) from None
        sid, secret = secrets.token_urlsafe(16), secrets.token_urlsafe(24)
        self._open[sid] = [session, time.monotonic(), secret]
        self.opened += 1
        return sid, secret, session

    def get(self, sid: str, secret: str) -> Session:
        """The session `sid` if `secret` is its own: 404 when unknown or expired, 403 on a wrong secret."""
        entry = self._open.get(sid)
        if entry is None or time.monotonic() - entry[1] > self.limits.timeout:
            if self._open.pop(sid, None) is not None:
                self.expired += 1
            raise BadRequest(404, f"unknown or expired session '{sid[:80]}' (sessions time out after "
                                  f"{self.limits.timeout:g} s idle; POST /reset opens one)", "SESSION_ERROR")
        if not hmac.compare_digest(entry[2].encode(), secret.encode()):
            raise BadRequest(403, f"wrong secret for session '{sid[:80]}' (send the secret /reset returned "
                                  "with it)", "SESSION_ERROR")
        entry[1] = time.monotonic()
        return entry[0]

    def close(self, sid: str, secret: str) -> None:
        """Forget a session (its secret checked as by `get`)."""
        self.get(sid, secret)
        del self._open[sid]

    def drop(self, sid: str) -> None:
        """Forget a session without a secret (its WebSocket connection ended)."""
        self._open.pop(sid, None)


def reset_args(body: dict, limits: Limits) -> dict:
    """Session.open's arguments from a reset body, every field checked (422 naming the bad one)."""
    unknown = set(body) - RESET_FIELDS
    if unknown:
        hint = " (the server makes session ids)" if unknown & {"episode_id"} else ""
        raise BadRequest(422, f"unknown field(s) {sorted(unknown)}{hint}; reset takes: "
                              f"{', '.join(sorted(RESET_FIELDS - {'session_id', 'secret'}))}")
    seed = field(body, "seed", int, 0)
    max_steps = field(body, "max_steps", int, MAX_STEPS)
    if not 0 <= seed <= MAX_SEED:
        raise BadRequest(422, f"seed must be in 0..2**63-1 (got {seed if abs(seed) < 10**30 else 'a huge number'})")
    if not 1 <= max_steps <= limits.max_steps:
        raise BadRequest(422, f"max_steps must be in 1..{limits.max_steps} (got {max_steps})")
    reward = field(body, "reward", str, "final")
    if reward not in REWARDS:
        raise BadRequest(422, f"unknown reward '{reward[:80]}' (choose from: {', '.join(REWARDS)})")
    prior = body.get("prior", [])
    if not (prior == "all" or (isinstance(prior, list) and all(isinstance(p, str) for p in prior))):
        raise BadRequest(422, "field 'prior' must be \"all\" or a list of preference ids or texts")
    return {"task": field(body, "task", str, None), "persona": field(body, "persona", str, None),
            "seed": seed, "reward": reward, "max_steps": max_steps, "prior": prior}


def state_of(sid: str, s: Session) -> dict:
    """The state answer: OpenEnv's episode_id and step_count, the episode's ids, and verdicts when over."""
    out = {"session_id": sid, "episode_id": sid, "step_count": s.env.world.step, "task": s.task,
           "seed": s.seed, "done": s.done, "max_steps": s.env.max_steps}
    if s.done:
        out["verdicts"] = s.evaluation().as_dict()
    return out


def _credentials(body: dict) -> tuple:
    return field(body, "session_id", str), field(body, "secret", str)


class Handlers:
    """The routes' logic on plain dicts (the ASGI layer only reads bodies and writes answers)."""

    def __init__(self, domain: CompiledDomain, limits: Limits):
        self.domain, self.sessions = domain, Sessions(domain, limits)

    def reset(self, body: dict) -> dict:
        """POST /reset: a new session. Naming the caller's own session (id and secret) closes it first;
        another's session is never touched (a wrong secret is 403 and nothing opens)."""
        args = reset_args(body, self.sessions.limits)
        old = field(body, "session_id", str, None)
        if old is not None:
            self.sessions.get(old, field(body, "secret", str))
        sid, secret, s = self.sessions.open(args, replacing=old is not None)
        if old is not None:
            self.sessions.drop(old)
        return {"session_id": sid, "secret": secret, "observation": {"text": s.opening(), "info": s.info()},
                "reward": None, "done": False}

    def step(self, body: dict) -> dict:
        """POST /step."""
        action = action_text(body, MAX_ACTION_CHARS)
        s = self.sessions.get(*_credentials(body))
        out = s.step(action)
        return {"observation": {"text": out.observation}, "reward": out.reward,
                "done": out.terminated or out.truncated, "terminated": out.terminated, "truncated": out.truncated,
                "info": out.info}

    def state(self, body: dict) -> dict:
        """GET /state."""
        sid, secret = _credentials(body)
        return state_of(sid, self.sessions.get(sid, secret))

    def close(self, body: dict) -> dict:
        """POST /close."""
        self.sessions.close(*_credentials(body))
        return {"closed": True}

    def health(self, body: dict) -> dict:
        """GET /health."""
        s = self.sessions
        return {"status": "healthy", "sessions": len(s), "opened": s.opened, "expired": s.expired}

    def info(self, body: dict) -> dict:
        """GET /info: what a client may ask for."""
        lim = self.sessions.limits
        return {"spec_hash": self.domain.spec_hash, "tasks": list(self.domain.task),
                "personas": list(self.domain.persona), "rewards": list(REWARDS), "max_steps": lim.max_steps,
                "max_sessions": lim.max_sessions, "timeout": lim.timeout, "request_timeout": lim.request_timeout,
                "max_action_chars": MAX_ACTION_CHARS, "max_body": MAX_BODY}


async def read_body(request, timeout: float) -> dict:
    """The request's JSON body (GET, DELETE: the query string), checked by `wire.parse_body`. A declared
    Content-Length over MAX_BODY is 413 unread; a body not complete within `timeout` s is 408."""
    if request.method in ("GET", "DELETE"):
        return {k: v for k, v in request.query_params.items()}
    declared = request.headers.get("content-length")
    if declared is not None and (not declared.isdigit() or int(declared) > MAX_BODY):
        raise BadRequest(413 if declared.isdigit() else 400,
                         f"Content-Length {declared[:40]} (a body is at most {MAX_BODY} bytes)")

    async def read() -> bytes:
        raw = b""
        async for chunk in request.stream():
            raw += chunk
            if len(raw) > MAX_BODY:
                raise BadRequest(413, f"request body over {MAX_BODY} bytes")
        return raw

    try:
        raw = await asyncio.wait_for(read(), timeout)
    except asyncio.TimeoutError:
        raise BadRequest(408, f"the request body did not arrive within {timeout:g} s (is Content-Length "
                              "right?)") from None
    return parse_body(raw)


def _response(content: dict, status: int = 200, close: bool = False):
    from starlette.responses import Response

    headers = {"connection": "close"} if close else None
    return Response(render(content), status_code=status, media_type="application/json", headers=headers)


def _http_route(handlers: Handlers, path: str, name: str, methods: list):
    from starlette.routing import Route

    method = getattr(handlers, name)
    timeout = handlers.sessions.limits.request_timeout

    async def endpoint(request):
        try:
            body = await read_body(request, timeout)
            if "sid" in request.path_params:
                body = {**body, "session_id": request.path_params["sid"]}
            return _response(method(body))
        except BadRequest as exc:
            return _response({"error": exc.message}, exc.status, close=exc.status in (408, 413))
        except Exception as exc:  # noqa: BLE001 - one request's bug must not end the server
            return _response({"error": f"internal error: {type(exc).__name__}: {exc}"}, 500)

    return Route(path, endpoint, methods=methods)


def create_app(domain: CompiledDomain, limits: Limits | None = None):
    """The ASGI app serving `domain` (a Starlette app; `app.state.handlers` holds the sessions)."""
    from starlette.applications import Starlette
    from starlette.routing import WebSocketRoute

    from .websocket import websocket_endpoint

    handlers = Handlers(domain, limits or Limits())

    async def reaper():
        while True:
            await asyncio.sleep(max(0.05, min(handlers.sessions.limits.timeout / 4, 30.0)))
            handlers.sessions.reap()

    @contextlib.asynccontextmanager
    async def lifespan(app):
        task = asyncio.create_task(reaper())
        yield
        task.cancel()

    routes = [_http_route(handlers, *r) for r in (
        ("/reset", "reset", ["POST"]), ("/step", "step", ["POST"]), ("/state", "state", ["GET", "POST"]),
        ("/close", "close", ["POST"]), ("/sessions/{sid}", "close", ["DELETE"]), ("/health", "health", ["GET"]),
        ("/info", "info", ["GET"]))]
    routes.append(WebSocketRoute("/ws", websocket_endpoint(handlers)))

    async def no_route(request, exc):
        path = request.url.path[:80]
        what = f"{request.method} is not allowed on {path}" if exc.status_code == 405 else f"no route {path!r}"
        return _response({"error": f"{what} (routes: {ROUTES})"}, exc.status_code)

    app = Starlette(routes=routes, lifespan=lifespan, exception_handlers={404: no_route, 405: no_route})
    app.state.handlers = handlers
    return app


def uvicorn_config(app, host: str, port: int, limits: Limits, log_level: str = "warning"):
    """uvicorn's Config for `app`: HTTP/1.1 with the request deadline (`envs.connections`), idle keep-alive
    connections closed after the same time, WebSocket messages capped at MAX_BODY."""
    import uvicorn

    from .connections import protocol_class

    return uvicorn.Config(app, host=host, port=port, log_level=log_level, access_log=False,
                          http=protocol_class(limits.request_timeout), ws="auto",
                          timeout_keep_alive=max(1, round(limits.request_timeout)), ws_max_size=MAX_BODY,
                          ws_ping_interval=None, ws_ping_timeout=None)


def serve(domain: CompiledDomain, host: str = "127.0.0.1", port: int = 8000, limits: Limits | None = None,
          log_level: str = "warning") -> None:
    """Serve until interrupted (uvicorn)."""
    import uvicorn

    limits = limits or Limits()
    uvicorn.Server(uvicorn_config(create_app(domain, limits), host, port, limits, log_level)).run()
