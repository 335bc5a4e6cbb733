"""ADAPT served over HTTP: many concurrent sessions, each its own episode (seed, persona, task), with
OpenEnv-style routes. A standard ASGI app (Starlette), run by uvicorn (`adapt serve-env --port 8000`).

    POST /reset   {"seed": 3, "task": "eggs", "persona": "juan", "reward": "final", "max_steps": 50}
                  -> {"session_id": "...", "observation": {"text": ..., "info": {...}}, "reward": null, "done": false}
    POST /step    {"session_id": "...", "action": {"text": "Look for eggs"}}   ("action": "Look for eggs" also works)
                  -> {"observation": {"text": ...}, "reward": 0.0, "done": false, "terminated": false,
                      "truncated": false, "info": {"step": 1, "ok": true, "action": "look_for", ...}}
    GET  /state?session_id=...   -> step count, task, done, verdicts once the episode is over
    POST /close   {"session_id": "..."}      (DELETE /sessions/{id} too)
    GET  /health, GET /info      (task and persona ids, limits)

Every bad request is answered with a 4xx and {"error": message}: malformed JSON (400), a body over the
size limit or an action over MAX_ACTION_CHARS (413), a missing or mistyped field, unknown task or
persona (422), an unknown or expired session (404), the session cap reached (429). A bug in one step is
a 500 for that request; the server goes on. Sessions idle longer than the time-out are dropped.

Steps run on the event loop itself (an episode step takes well under a millisecond, and a single thread
needs no locks): requests of different sessions interleave, each session's requests are served in order.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
import uuid
from dataclasses import dataclass

from ..compiler.model import CompiledDomain
from ..runtime.env import MAX_STEPS
from .session import MAX_ACTION_CHARS, REWARDS, Session

MAX_BODY = 64 * 1024


class BadRequest(Exception):
    """A request the server refuses: HTTP status and message."""

    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status, self.message = status, message


@dataclass
class Limits:
    """Server limits: concurrent sessions, idle time-out (seconds), largest step limit a client may ask."""

    max_sessions: int = 1024
    timeout: float = 600.0
    max_steps: int = 200


class Sessions:
    """The open sessions, by id, with their last use; idle ones are dropped by `reap`."""

    def __init__(self, domain: CompiledDomain, limits: Limits):
        self.domain, self.limits = domain, limits
        self._open: dict = {}  # id -> [Session, last use]
        self.opened = self.expired = 0

    def __len__(self) -> int:
        return len(self._open)

    def reap(self, now: float | None = None) -> int:
        """Drop sessions idle longer than the time-out; returns how many."""
        now = time.monotonic() if now is None else now
        old = [sid for sid, (_, used) in self._open.items() if now - used > self.limits.timeout]
        for sid in old:
            del self._open[sid]
        self.expired += len(old)
        return len(old)

    def open(self, body: dict) -> tuple:
        """A new session from a reset body; returns (id, Session)."""
        self.reap()
        sid = _field(body, "session_id", str, None) or _field(body, "episode_id", str, None) or uuid.uuid4().hex
        if sid not in self._open and len(self._open) >= self.limits.max_sessions:
            raise BadRequest(429, f"the server holds its maximum of {self.limits.max_sessions} sessions; "
                                  "close one or wait for idle ones to time out")
        session = Session.open(self.domain, **_reset_args(body, self.limits))
        self._open[sid] = [session, time.monotonic()]
        self.opened += 1
        return sid, session

    def get(self, body: dict) -> tuple:
        """(id, Session) named by the body's session_id; 404 when unknown or expired."""
        sid = _field(body, "session_id", str)
        entry = self._open.get(sid)
        if entry is None or time.monotonic() - entry[1] > self.limits.timeout:
            if self._open.pop(sid, None) is not None:
                self.expired += 1
            raise BadRequest(404, f"unknown or expired session '{sid[:80]}' (sessions time out after "
                                  f"{self.limits.timeout:g} s idle; POST /reset opens one)")
        entry[1] = time.monotonic()
        return sid, entry[0]

    def close(self, sid: str) -> bool:
        """Forget a session; whether it was open."""
        return self._open.pop(sid, None) is not None


def _field(body: dict, name: str, kind, default=...):
    value = body.get(name, default)
    if value is ...:
        raise BadRequest(422, f"missing field '{name}'")
    if value is not None and value is not default and (not isinstance(value, kind) or isinstance(value, bool)):
        raise BadRequest(422, f"field '{name}' must be {kind.__name__}, not {type(value).__name__}")
    return value


def _reset_args(body: dict, limits: Limits) -> dict:
    unknown = set(body) - {"seed", "task", "persona", "reward", "max_steps", "prior", "session_id", "episode_id"}
    if unknown:
        raise BadRequest(422, f"unknown field(s) {sorted(unknown)}")
    seed = _field(body, "seed", int, 0)
    max_steps = _field(body, "max_steps", int, MAX_STEPS)
    if seed < 0:
        raise BadRequest(422, f"seed must be >= 0 (got {seed})")
    if not 1 <= max_steps <= limits.max_steps:
        raise BadRequest(422, f"max_steps must be in 1..{limits.max_steps} (got {max_steps})")
    reward = _field(body, "reward", str, "final")
    if reward not in REWARDS:
        raise BadRequest(422, f"unknown reward '{reward}' (choose from: {', '.join(REWARDS)})")
    prior = body.get("prior", ())
    if not (prior == "all" or (isinstance(prior, list | tuple) and all(isinstance(p, str) for p in prior))):
        raise BadRequest(422, "field 'prior' must be \"all\" or a list of preference ids or texts")
    return {"task": _field(body, "task", str, None), "persona": _field(body, "persona", str, None),
            "seed": seed, "reward": reward, "max_steps": max_steps, "prior": prior}


def _action(body: dict) -> str:
    action = body.get("action")
    if isinstance(action, dict):
        action = action.get("text", action.get("action"))
    if not isinstance(action, str):
        raise BadRequest(422, "field 'action' must be a string or {\"text\": string}")
    if len(action) > MAX_ACTION_CHARS:
        raise BadRequest(413, f"action is {len(action)} characters (at most {MAX_ACTION_CHARS})")
    return action


def state_of(sid: str, s: Session) -> dict:
    """The /state answer: OpenEnv's episode_id and step_count, the episode's ids, and verdicts when over."""
    out = {"session_id": sid, "episode_id": sid, "step_count": s.env.world.step, "task": s.task,
           "seed": s.seed, "done": s.done, "max_steps": s.env.max_steps}
    if s.done:
        out["verdicts"] = s.evaluation().as_dict()
    return out


class Handlers:
    """The routes' logic on plain dicts (the ASGI layer only reads bodies and writes answers)."""

    def __init__(self, domain: CompiledDomain, limits: Limits):
        self.domain, self.sessions = domain, Sessions(domain, limits)

    def reset(self, body: dict) -> dict:
        """POST /reset."""
        try:
            sid, s = self.sessions.open(body)
        except (KeyError, ValueError) as exc:
            raise BadRequest(422, str(exc).strip("'\"")) from exc
        return {"session_id": sid, "observation": {"text": s.opening(), "info": s.info()}, "reward": None,
                "done": False}

    def step(self, body: dict) -> dict:
        """POST /step."""
        action = _action(body)
        _, s = self.sessions.get(body)
        out = s.step(action)
        return {"observation": {"text": out.observation}, "reward": out.reward,
                "done": out.terminated or out.truncated, "terminated": out.terminated, "truncated": out.truncated,
                "info": out.info}

    def state(self, body: dict) -> dict:
        """GET /state."""
        return state_of(*self.sessions.get(body))

    def close(self, body: dict) -> dict:
        """POST /close."""
        return {"closed": self.sessions.close(_field(body, "session_id", str))}

    def health(self, body: dict) -> dict:
        """GET /health."""
        s = self.sessions
        return {"status": "healthy", "sessions": len(s), "opened": s.opened, "expired": s.expired}

    def info(self, body: dict) -> dict:
        """GET /info: what a client may ask for."""
        lim = self.sessions.limits
        return {"spec_hash": self.domain.spec_hash, "tasks": list(self.domain.task),
                "personas": list(self.domain.persona), "rewards": list(REWARDS), "max_steps": lim.max_steps,
                "max_sessions": lim.max_sessions, "timeout": lim.timeout, "max_action_chars": MAX_ACTION_CHARS}


async def _body(request) -> dict:
    if request.method == "GET":
        return dict(request.query_params)
    raw = b""
    async for chunk in request.stream():
        raw += chunk
        if len(raw) > MAX_BODY:
            raise BadRequest(413, f"request body over {MAX_BODY} bytes")
    if not raw:
        return {}
    try:
        body = json.loads(raw)
    except (ValueError, UnicodeDecodeError) as exc:
        raise BadRequest(400, f"malformed JSON: {exc}") from exc
    if not isinstance(body, dict):
        raise BadRequest(400, f"the body must be a JSON object, not {type(body).__name__}")
    return body


def create_app(domain: CompiledDomain, limits: Limits | None = None):
    """The ASGI app serving `domain` (a Starlette app; `app.state.handlers` holds the sessions)."""
    from starlette.applications import Starlette
    from starlette.responses import JSONResponse
    from starlette.routing import Route

    handlers = Handlers(domain, limits or Limits())

    def route(path: str, name: str, methods: list):
        method = getattr(handlers, name)

        async def endpoint(request):
            try:
                body = await _body(request)
                if "sid" in request.path_params:
                    body = {"session_id": request.path_params["sid"]}
                return JSONResponse(method(body))
            except BadRequest as exc:
                return JSONResponse({"error": exc.message}, status_code=exc.status)
            except Exception as exc:  # noqa: BLE001 - one request's bug must not end the server
                return JSONResponse({"error": f"internal error: {type(exc).__name__}: {exc}"}, status_code=500)

        return Route(path, endpoint, methods=methods)

    async def reaper():
        while True:
            await asyncio.sleep(max(0.05, min(handlers.sessions.limits.timeout / 4, 30.0)))
            handlers.sessions.reap()

    @contextlib.asynccontextmanager
    async def lifespan(app):
        task = asyncio.create_task(reaper())
        yield
        task.cancel()

    app = Starlette(routes=[
        route("/reset", "reset", ["POST"]), route("/step", "step", ["POST"]),
        route("/state", "state", ["GET", "POST"]), route("/close", "close", ["POST"]),
        route("/sessions/{sid}", "close", ["DELETE"]), route("/health", "health", ["GET"]),
        route("/info", "info", ["GET"])], lifespan=lifespan)
    app.state.handlers = handlers
    return app


def serve(domain: CompiledDomain, host: str = "127.0.0.1", port: int = 8000, limits: Limits | None = None,
          log_level: str = "warning") -> None:
    """Serve until interrupted (uvicorn)."""
    import uvicorn

    uvicorn.run(create_app(domain, limits), host=host, port=port, log_level=log_level, access_log=False)
