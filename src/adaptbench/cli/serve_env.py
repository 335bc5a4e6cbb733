"""`adapt serve-env`: the environment over HTTP and OpenEnv's WebSocket protocol (docs/environments.md, *Server*)."""

from __future__ import annotations

import sys

from .argtypes import positive
from .episode import add_spec_option


def _port(text: str) -> int:
    import argparse

    value = positive(text)
    if value > 65535:
        raise argparse.ArgumentTypeError(f"port {text} is out of range (1 to 65535)")
    return value


def _unbindable(host: str, port: int) -> str | None:
    """Why the address cannot be listened on (in use, unknown host), or None."""
    import socket

    try:
        with socket.socket() as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.bind((host, port))
    except OSError as exc:
        return exc.strerror or str(exc)
    return None


def _cmd_serve_env(args) -> int:
    import importlib.util

    missing = [m for m in ("starlette", "uvicorn", "websockets") if importlib.util.find_spec(m) is None]
    if missing:
        print(f"adapt: serve-env needs {' and '.join(missing)}: pip install 'adaptbench[envs]'", file=sys.stderr)
        return 1
    from ..compiler import load_domain
    from ..envs.server import Limits, serve

    domain = load_domain(args.spec)
    problem = _unbindable(args.host, args.port)
    if problem:
        print(f"adapt: cannot listen on {args.host}:{args.port}: {problem}", file=sys.stderr)
        return 1
    limits = Limits(max_sessions=args.max_sessions, timeout=float(args.timeout), max_steps=args.max_steps,
                    request_timeout=float(args.request_timeout))
    print(f"adapt: serving {args.spec} (spec {domain.spec_hash}) on http://{args.host}:{args.port} and "
          f"ws://{args.host}:{args.port}/ws (at most {limits.max_sessions} sessions, {limits.timeout:g} s idle "
          f"session time-out, {limits.request_timeout:g} s request time-out); Ctrl-C stops",
          file=sys.stderr, flush=True)
    serve(domain, args.host, args.port, limits, args.log_level)
    return 0


def add_commands(sub) -> None:
    """Register serve-env."""
    p = sub.add_parser("serve-env", help="serve the environment over HTTP and WebSocket (many concurrent sessions)",
                       description="Serve ADAPT episodes: OpenEnv's WebSocket protocol at /ws (openenv-core's "
                                   "GenericEnvClient) and HTTP routes POST /reset, POST /step, GET /state, "
                                   "POST /close, GET /health, GET /info. Each session is its own episode (seed, "
                                   "persona, task), named by an id and a secret the server makes; see "
                                   "docs/environments.md.")
    add_spec_option(p)
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=_port, default=8000, help="port (default 8000)")
    p.add_argument("--max-sessions", type=positive, default=1024, help="cap on open sessions (default 1024)")
    p.add_argument("--timeout", type=positive, default=600, help="seconds an idle session is kept (default 600)")
    p.add_argument("--request-timeout", type=positive, default=10,
                   help="seconds a connection has to send a request's headers (from connecting or the previous "
                        "answer), and then its body; idle, trickling or short-bodied connections are closed "
                        "(default 10)")
    p.add_argument("--max-steps", type=positive, default=200, help="largest step limit a client may ask (default 200)")
    p.add_argument("--log-level", default="warning", choices=["critical", "error", "warning", "info", "debug"],
                   help="uvicorn's log level (default warning)")
    p.set_defaults(func=_cmd_serve_env)
