"""Connections that hold the server without finishing a request are closed: uvicorn's HTTP/1.1 protocol
(h11) with a request deadline. A connection must deliver a request's complete headers within
`request_timeout` seconds of opening, or of the previous answer; an idle connection (nothing sent), a
trickling one (a byte now and then) and a half-sent request line are closed when it passes, whatever
they send meanwhile. The body's own deadline (a Content-Length that promises more bytes than come) is
the app's: `server.read_body` answers 408. A WebSocket is past this stage once upgraded (its idle limit
is the session time-out). A request h11 cannot parse (a bad request line, header or Content-Length) is
answered 400 with a JSON message, as every other refusal, and the connection closed.
"""

from __future__ import annotations

import asyncio
import contextlib
import json

from uvicorn.protocols.http.h11_impl import H11Protocol


class DeadlineH11Protocol(H11Protocol):
    """H11Protocol whose connections are closed when a request's headers are not complete in time."""

    request_timeout = 10.0  # set per server by `protocol_class`

    def connection_made(self, transport) -> None:  # noqa: D102 - asyncio.Protocol
        super().connection_made(transport)
        self._deadline: asyncio.TimerHandle | None = None
        self._arm()

    def connection_lost(self, exc) -> None:  # noqa: D102 - asyncio.Protocol
        self._disarm()
        super().connection_lost(exc)

    def handle_events(self) -> None:  # noqa: D102 - a new request's headers stop the clock
        cycle = self.cycle
        super().handle_events()
        if self.cycle is not cycle:
            self._disarm()

    def on_response_complete(self) -> None:  # noqa: D102 - the next request's clock starts at the answer
        self._arm()
        super().on_response_complete()

    def handle_websocket_upgrade(self, event) -> None:  # noqa: D102
        self._disarm()
        super().handle_websocket_upgrade(event)

    def send_400_response(self, msg: str) -> None:  # noqa: D102 - a request h11 cannot parse: 400 in JSON
        import h11

        body = json.dumps({"error": f"{msg.rstrip('.')} (not an HTTP/1.1 request h11 can parse)"}).encode()
        headers = [(b"content-type", b"application/json"), (b"connection", b"close"),
                   (b"content-length", str(len(body)).encode())]
        with contextlib.suppress(h11.LocalProtocolError):
            self.transport.write(self.conn.send(h11.Response(status_code=400, headers=headers, reason=b"Bad Request")))
            self.transport.write(self.conn.send(h11.Data(data=body)))
            self.transport.write(self.conn.send(h11.EndOfMessage()))
        self.transport.close()

    def _arm(self) -> None:
        self._disarm()
        self._deadline = self.loop.call_later(self.request_timeout, self._expire)

    def _disarm(self) -> None:
        if getattr(self, "_deadline", None) is not None:
            self._deadline.cancel()
            self._deadline = None

    def _expire(self) -> None:
        self._deadline = None
        if self.transport.is_closing() or (self.cycle is not None and not self.cycle.response_complete):
            return  # a request in progress is the app's to time out
        self.transport.close()


def protocol_class(request_timeout: float) -> type:
    """A DeadlineH11Protocol subclass with this server's request time-out."""
    return type("DeadlineH11Protocol", (DeadlineH11Protocol,), {"request_timeout": float(request_timeout)})
