"""A relay in front of an OpenAI-compatible server whose streams end without `data: [DONE]` (`transformers
serve` 5.x): every request is forwarded as is, and a streamed answer (`text/event-stream`) that closes
without the sentinel gets it, so clients that end a turn on it (`verifiers` 0.4: its interception server
withholds the turn until `[DONE]`) finish their turn. Non-streamed answers pass through unchanged.

    transformers serve models/tiny --device cpu --port 8000 &
    python -m adaptbench.envs.sse_relay --upstream http://127.0.0.1:8000 --port 8001 &
    # then point the client at http://127.0.0.1:8001/v1

A Starlette app over httpx (both come with the `envs` and `verifiers` extras).
"""

from __future__ import annotations

import argparse

DONE = b"data: [DONE]\n\n"
HOP_HEADERS = {"host", "content-length", "connection", "keep-alive", "transfer-encoding", "accept-encoding"}


def ensure_done(chunks):
    """An async generator over `chunks` (bytes of an SSE stream) that ends with the [DONE] sentinel,
    adding it (after a blank line, if the last event was left open) when the stream had none."""

    async def gen():
        tail = b""
        async for chunk in chunks:
            if chunk:
                tail = (tail + chunk)[-256:]
                yield chunk
        if tail.rstrip().endswith(b"data: [DONE]"):
            return
        yield (b"" if tail.endswith(b"\n\n") or not tail else b"\n\n" if not tail.endswith(b"\n") else b"\n") + DONE

    return gen()


def create_app(upstream: str, timeout: float = 600.0):
    """The relay's ASGI app forwarding every path to `upstream` (scheme://host:port)."""
    import httpx
    from starlette.applications import Starlette
    from starlette.background import BackgroundTask
    from starlette.responses import Response, StreamingResponse
    from starlette.routing import Route

    client = httpx.AsyncClient(base_url=upstream.rstrip("/"), timeout=timeout)

    async def relay(request):
        headers = {k: v for k, v in request.headers.items() if k.lower() not in HOP_HEADERS}
        req = client.build_request(request.method, request.url.path, params=request.query_params,
                                   content=await request.body(), headers=headers)
        try:
            resp = await client.send(req, stream=True)
        except httpx.HTTPError as exc:
            return Response(f'{{"error": {{"message": "no answer from {upstream}: {type(exc).__name__}"}}}}',
                            status_code=502, media_type="application/json")
        kind = resp.headers.get("content-type", "")
        if "text/event-stream" not in kind:
            data = await resp.aread()
            await resp.aclose()
            return Response(data, status_code=resp.status_code, media_type=kind or None)
        return StreamingResponse(ensure_done(resp.aiter_raw()), status_code=resp.status_code,
                                 media_type="text/event-stream", background=BackgroundTask(resp.aclose))

    methods = ["GET", "POST", "PUT", "DELETE", "PATCH", "OPTIONS"]
    return Starlette(routes=[Route("/{path:path}", relay, methods=methods)])


def main(argv=None) -> int:
    """`python -m adaptbench.envs.sse_relay --upstream URL [--host H] [--port P]`."""
    import uvicorn

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--upstream", required=True, help="the server to relay to, e.g. http://127.0.0.1:8000")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=8001, help="port (default 8001)")
    args = p.parse_args(argv)
    uvicorn.run(create_app(args.upstream), host=args.host, port=args.port, log_level="warning", access_log=False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
