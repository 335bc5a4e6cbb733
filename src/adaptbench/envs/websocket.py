"""OpenEnv's WebSocket protocol at `/ws`, as `openenv-core`'s `EnvClient` and `GenericEnvClient` speak it
(openenv/core/env_client.py, env_server/http_server.py): one JSON message per frame,

    {"type": "reset", "data": {"seed": 3, "task": "eggs", ...}}  -> {"type": "observation", "data": {...}}
    {"type": "step", "data": {"text": "Look for eggs"}}         -> {"type": "observation", "data": {...}}
    {"type": "state"}                                            -> {"type": "state", "data": {...}}
    {"type": "close"}                                            (the server closes the connection)

An observation's data is {"observation": {"text", "info", "terminated", "truncated"}, "reward", "done"}
(OpenEnv's `serialize_observation` shape: everything but reward and done inside `observation`). A refused
message is answered {"type": "error", "data": {"message", "code", "status"}} with OpenEnv's error codes and
the HTTP route's status, and the connection stays open. The connection owns its session: a reset replaces
only this connection's episode, the session ends with the connection, and a connection silent longer
than the session time-out is closed (code 1001).
"""

from __future__ import annotations

import asyncio
import contextlib
import time

from .server import Handlers, reset_args, state_of
from .session import MAX_ACTION_CHARS
from .wire import BadRequest, action_text, field, parse_body, render

MESSAGE_KEYS = {"type", "data"}


class Connection:
    """One WebSocket's session (none before its first reset) and its messages' logic."""

    def __init__(self, handlers: Handlers):
        self.sessions = handlers.sessions
        self.sid: str | None = None
        self.secret: str | None = None

    def answer(self, message: dict) -> dict:
        """The reply to one parsed message (BadRequest when refused)."""
        unknown = set(message) - MESSAGE_KEYS
        if unknown:
            raise BadRequest(422, f"unknown key(s) {sorted(unknown)} in the message (keys: type, data)")
        kind = message.get("type")
        if kind == "reset":
            return self.reset(field(message, "data", dict, {}))
        if kind == "step":
            return self.step(field(message, "data", dict))
        if kind == "state":
            return {"type": "state", "data": state_of(self.sid, self.session())}
        raise BadRequest(400, f"unknown message type {str(kind)[:40]!r} (reset, step, state, close)", "UNKNOWN_TYPE")

    def reset(self, data: dict) -> dict:
        """A new episode for this connection (its previous one, if any, is closed)."""
        if "session_id" in data or "secret" in data:
            raise BadRequest(422, "a WebSocket connection owns its session: reset takes no session_id or secret")
        args = reset_args(data, self.sessions.limits)
        sid, secret, s = self.sessions.open(args, replacing=self.sid is not None)
        self.end()
        self.sid, self.secret = sid, secret
        return {"type": "observation", "data": {
            "observation": {"text": s.opening(), "info": s.info(), "terminated": False, "truncated": False},
            "reward": None, "done": False, "session_id": sid}}

    def step(self, data: dict) -> dict:
        """One action in this connection's episode."""
        action = action_text(data, MAX_ACTION_CHARS)
        out = self.session().step(action)
        return {"type": "observation", "data": {
            "observation": {"text": out.observation, "info": out.info, "terminated": out.terminated,
                            "truncated": out.truncated},
            "reward": out.reward, "done": out.terminated or out.truncated}}

    def session(self):
        """This connection's session (409 before a reset; 404 once it timed out)."""
        if self.sid is None:
            raise BadRequest(409, "no episode on this connection yet: send {\"type\": \"reset\"} first",
                             "SESSION_ERROR")
        return self.sessions.get(self.sid, self.secret)

    def end(self) -> None:
        """Close this connection's session, if any."""
        if self.sid is not None:
            self.sessions.drop(self.sid)
            self.sid = self.secret = None


def _error(exc: BadRequest) -> dict:
    return {"type": "error", "data": {"message": exc.message, "code": exc.code, "status": exc.status}}


def reply_to(conn: Connection, raw) -> dict | None:
    """The reply to one frame's payload (text or bytes), or None for a close message."""
    try:
        message = parse_body(raw)
        if message.get("type") == "close":
            return None
        return conn.answer(message)
    except BadRequest as exc:
        return _error(exc)
    except Exception as exc:  # noqa: BLE001 - one message's bug must not end the connection
        return _error(BadRequest(500, f"internal error: {type(exc).__name__}: {exc}", "EXECUTION_ERROR"))


def websocket_endpoint(handlers: Handlers):
    """The Starlette WebSocket endpoint of `/ws` over `handlers`' sessions."""
    idle = handlers.sessions.limits.timeout

    async def endpoint(websocket):
        await websocket.accept()
        conn = Connection(handlers)
        last = [time.monotonic()]
        watchdog = asyncio.create_task(_close_when_idle(websocket, last, idle, asyncio.current_task()))
        try:
            while True:
                message = await websocket.receive()
                last[0] = time.monotonic()
                if message["type"] == "websocket.disconnect":
                    return
                reply = reply_to(conn, message.get("text") or message.get("bytes") or b"")
                if reply is None:
                    await websocket.close(code=1000)
                    return
                await websocket.send_text(render(reply).decode("utf-8"))
        except Exception:  # noqa: BLE001 - the peer vanished mid-send
            return
        except asyncio.CancelledError:
            if not watchdog.done() or watchdog.cancelled():
                raise  # the server is shutting down
            return  # the watchdog ended an idle connection
        finally:
            watchdog.cancel()
            conn.end()

    return endpoint


async def _close_when_idle(websocket, last: list, idle: float, endpoint) -> None:
    """Close the connection once nothing has arrived for `idle` seconds and end its endpoint (one timer
    per connection rather than a time-out around every receive)."""
    while True:
        wait = last[0] + idle - time.monotonic()
        if wait <= 0:
            with contextlib.suppress(Exception):
                await websocket.close(code=1001, reason=f"idle for {idle:g} s")
            endpoint.cancel()
            return
        await asyncio.sleep(wait)
