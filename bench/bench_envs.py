"""The RL interfaces' speed and faithfulness: `python bench/bench_envs.py [--quick] [--sessions 1,16,64,256]
[--ws-sessions 64,256]`.

1. In-process: the same oracle episodes replayed through the simulator itself (`Env.step`, then the
   verifiers) and through the Gymnasium env (`gym.make("adaptbench/Breakfast-v0")`, reset, step), in
   the same run: steps per second of each and their ratio (target: Gymnasium >= 0.8x the simulator).
2. Server: `adapt serve-env` on loopback in its own process; N concurrent client sessions (one thread and
   one kept-alive connection each) play the oracle's actions of distinct (persona, task, seed) episodes;
   steps per second, p50/p99 step latency, errors, and every session's verdicts compared with the same
   episode run in-process (target: 0 errors, 0 mismatches).
3. The same server through OpenEnv's WebSocket route `/ws`: N concurrent connections (one asyncio task
   each, OpenEnv's messages), the same measures.

The oracle's actions are computed once, in-process, before timing (`agents.scripted.play`).
"""

from __future__ import annotations

import argparse
import os
import random
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import ROOT, SPEC, report  # noqa: E402


def oracle_episodes(domain, n: int, seed0: int = 0) -> list:
    """n distinct episodes (task, persona, seed, actions, verdicts) played by the oracle in-process."""
    from adaptbench.agents.scripted import play
    from adaptbench.envs.session import Session

    rng = random.Random(seed0)
    combos = [(t.id, p.id) for t in domain.tasks for p in domain.personas]
    rng.shuffle(combos)
    out = []
    for i in range(n):
        task, persona = combos[i % len(combos)]
        seed = seed0 + i // len(combos)
        s = Session.open(domain, task, persona, seed)
        ep = play("oracle", s.env, f"oracle/{persona}/{task}/{seed}")
        out.append({"task": task, "persona": persona, "seed": seed, "actions": [st.action for st in ep.steps],
                    "verdicts": s.env.evaluate().as_dict()})
    return out


def bench_inprocess(domain, episodes: list, reps: int) -> list:
    """Steps/s of the simulator and of the Gymnasium env on the same episodes (best of `reps` rounds each)."""
    import gymnasium as gym

    import adaptbench.envs  # noqa: F401 - registers the env
    from adaptbench.agents.users import OfflineUser
    from adaptbench.runtime.env import Env

    steps = sum(len(e["actions"]) for e in episodes)

    def simulator():
        for e in episodes:
            env = Env(domain, e["task"], e["persona"], e["seed"],
                      user=OfflineUser(domain, domain.persona[e["persona"]], domain.task[e["task"]]))
            env.reset()
            for a in e["actions"]:
                env.step(a)
            env.evaluate()

    genv = gym.make("adaptbench/Breakfast-v0", spec=domain)

    def gymnasium():
        for e in episodes:
            genv.reset(seed=e["seed"], options={"task": e["task"], "persona": e["persona"]})
            for a in e["actions"]:
                genv.step(a)

    sim_t, gym_t = _best_interleaved(simulator, gymnasium, reps)
    ratio = sim_t / gym_t
    return [("in-process simulator steps/s (oracle episodes)", steps / sim_t, "steps/s", "-",
             f"{steps} steps over {len(episodes)} episodes, verdicts at each end"),
            ("in-process Gymnasium steps/s (same episodes)", steps / gym_t, "steps/s", ">= 0.8x sim",
             f"{ratio:.2f}x the simulator's own, same run")]


def _best_interleaved(a, b, reps: int) -> tuple:
    """Best time of each of two functions, run alternately (a shared machine's load hits both alike)."""
    times: tuple = ([], [])
    for _ in range(reps):
        for fn, out in zip((a, b), times, strict=True):
            t = time.perf_counter()
            fn()
            out.append(time.perf_counter() - t)
    return min(times[0]), min(times[1])


def free_port() -> int:
    """A free TCP port on loopback."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_server(spec, port: int, max_sessions: int = 1024, timeout: int = 600) -> subprocess.Popen:
    """`adapt serve-env` in a child process, once it answers /health."""
    from adaptbench.envs.client import EnvClient

    proc = subprocess.Popen([sys.executable, "-m", "adaptbench.cli", "serve-env", "--spec", str(spec), "--port",
                             str(port), "--max-sessions", str(max_sessions), "--timeout", str(timeout)],
                            cwd=ROOT, stderr=subprocess.DEVNULL, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"adapt serve-env exited with {proc.returncode}")
        try:
            EnvClient(f"http://127.0.0.1:{port}", timeout=1).health()
            return proc
        except OSError:
            time.sleep(0.2)
    proc.kill()
    raise RuntimeError("adapt serve-env did not answer /health within 60 s")


def play_remote(url: str, episode: dict) -> tuple:
    """Play one episode's actions on the server: (per-step latencies, verdicts, error or None)."""
    from adaptbench.envs.client import EnvClient

    lat = []
    try:
        with EnvClient(url) as c:
            c.reset(seed=episode["seed"], task=episode["task"], persona=episode["persona"])
            out = {}
            for a in episode["actions"]:
                t = time.perf_counter()
                out = c.step(a)
                lat.append(time.perf_counter() - t)
                if out["done"]:
                    break
            verdicts = out.get("info", {}).get("verdicts") or c.state().get("verdicts")
        return lat, verdicts, None
    except Exception as exc:  # noqa: BLE001 - counted as the session's error
        return lat, None, f"{type(exc).__name__}: {exc}"


async def play_ws(url: str, episode: dict) -> tuple:
    """Play one episode over `/ws` with OpenEnv's messages: (per-step latencies, verdicts, error or None)."""
    import json

    from websockets.asyncio.client import connect

    lat = []
    try:
        async with connect(url, max_size=1 << 20, open_timeout=60) as ws:
            async def call(message: dict) -> dict:
                await ws.send(json.dumps(message))
                out = json.loads(await ws.recv())
                if out["type"] == "error":
                    raise RuntimeError(out["data"]["message"])
                return out["data"]

            await call({"type": "reset", "data": {k: episode[k] for k in ("seed", "task", "persona")}})
            out = {}
            for a in episode["actions"]:
                t = time.perf_counter()
                out = await call({"type": "step", "data": {"text": a}})
                lat.append(time.perf_counter() - t)
                if out["done"]:
                    break
            verdicts = out["observation"]["info"].get("verdicts") or (await call({"type": "state"})).get("verdicts")
            await ws.send(json.dumps({"type": "close"}))
        return lat, verdicts, None
    except Exception as exc:  # noqa: BLE001 - counted as the session's error
        return lat, None, f"{type(exc).__name__}: {exc}"


def load_ws(url: str, episodes: list, sessions: int, rounds: int) -> dict:
    """`sessions` WebSocket connections at once (asyncio tasks), each playing `rounds` episodes."""
    import asyncio

    results = []

    async def worker(k: int):
        for r in range(rounds):
            e = episodes[(k + r * sessions) % len(episodes)]
            lat, verdicts, err = await play_ws(url, e)
            results.append((lat, err, err is None and verdicts != e["verdicts"]))

    async def main():
        await asyncio.gather(*(worker(k) for k in range(sessions)))

    t = time.perf_counter()
    asyncio.run(main())
    return _figures(results, sessions, time.perf_counter() - t)


def load(url: str, episodes: list, sessions: int, rounds: int) -> dict:
    """`sessions` client threads at once, each playing `rounds` episodes (distinct per session)."""
    results, lock = [], threading.Lock()

    def worker(k: int):
        for r in range(rounds):
            e = episodes[(k + r * sessions) % len(episodes)]
            lat, verdicts, err = play_remote(url, e)
            with lock:
                results.append((lat, err, err is None and verdicts != e["verdicts"]))

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(sessions)]
    t = time.perf_counter()
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    return _figures(results, sessions, time.perf_counter() - t)


def _figures(results: list, sessions: int, wall: float) -> dict:
    lats = sorted(x for lat, _, _ in results for x in lat)
    return {"sessions": sessions, "episodes": len(results), "steps": len(lats), "wall": wall,
            "steps_per_s": len(lats) / wall, "p50_ms": 1e3 * _q(lats, 0.50), "p99_ms": 1e3 * _q(lats, 0.99),
            "errors": sum(err is not None for _, err, _ in results),
            "mismatches": sum(m for _, _, m in results),
            "error_samples": [err for _, err, _ in results if err][:3]}


def _q(xs: list, q: float) -> float:
    return xs[min(len(xs) - 1, int(q * len(xs)))] if xs else float("nan")


def bench_server(spec, episodes: list, levels: list, ws_levels: list, total: int) -> tuple:
    """Rows for each concurrency level over HTTP, then over /ws (each plays at least `total` episodes, so
    that one session's figures rest on as many steps as 64 sessions'), and the raw figures."""
    port = free_port()
    proc = start_server(spec, port)
    rows, figures = [], []
    runs = [("HTTP", load, f"http://127.0.0.1:{port}", n) for n in levels]
    runs += [("WebSocket /ws", load_ws, f"ws://127.0.0.1:{port}/ws", n) for n in ws_levels]
    try:
        for route, run, url, n in runs:
            f = run(url, episodes, n, -(-total // n))
            f["route"] = route
            figures.append(f)
            rows.append((f"server steps/s, {route}, {n} concurrent sessions", f["steps_per_s"], "steps/s",
                         "0 errors", f"p50 {f['p50_ms']:.2f} ms, p99 {f['p99_ms']:.2f} ms, {f['episodes']} episodes, "
                         f"{f['errors']} errors, {f['mismatches']} verdict mismatches"))
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    return rows, figures


def main() -> int:
    """Run the benchmark and print its rows; exit 1 on any server error or verdict mismatch."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer episodes (CI)")
    parser.add_argument("--sessions", default="1,16,64,256", help="HTTP concurrency levels (default 1,16,64,256)")
    parser.add_argument("--ws-sessions", default="64,256", help="WebSocket concurrency levels (default 64,256)")
    parser.add_argument("--spec", default=str(SPEC), help="spec directory")
    args = parser.parse_args()
    from adaptbench.compiler import load_domain

    domain = load_domain(args.spec)
    levels = [int(x) for x in args.sessions.split(",") if x]
    ws_levels = [int(x) for x in args.ws_sessions.split(",") if x]
    if args.quick and args.sessions == parser.get_default("sessions"):
        levels = [1, 16, 64]  # CI: 256 sessions only through /ws (one episode each)
    episodes = oracle_episodes(domain, 8 if args.quick else max(levels + ws_levels))
    rows = bench_inprocess(domain, episodes, 10 if args.quick else 20)
    server_rows, figures = bench_server(args.spec, episodes, levels, ws_levels,
                                        len(episodes) if args.quick else 2 * len(episodes))
    report(rows + server_rows)
    bad = [f for f in figures if f["errors"] or f["mismatches"]]
    for f in bad:
        print(f"FAIL at {f['sessions']} sessions ({f['route']}): {f['errors']} errors {f['error_samples']}, "
              f"{f['mismatches']} mismatches", file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
