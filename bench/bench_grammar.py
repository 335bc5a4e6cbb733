"""Per-state action grammars: a new state's grammar from the cached base, the incremental update
after one observation, against rebuilding from scratch (index + base + terminals) and against what
an engine then spends building its parser on the text (python-lark; llguidance when installed)."""

from __future__ import annotations

import statistics
import time

from adaptbench.compiler import load_domain
from adaptbench.grammars import GrammarCache, Observed, StateGrammar, build_base, build_index
from adaptbench.runtime.env import Env

from .common import SPEC, episode_actions, report, timeit


def _full_state(domain) -> Observed:
    env = Env(domain, "eggs", seed=None, full_scene=True)
    return Observed(frozenset(env.world.specs), frozenset(domain.substance))


def _per_update(domain, cache, reps: int) -> tuple[float, float]:
    """(median, max) seconds of `update` over the steps of the 50-step replay where the state grew."""
    times = []
    for _ in range(reps):
        env = Env(domain, "toast_coffee", seed=None, full_scene=True)
        env.reset()
        g = cache.state("toast_coffee", env.observed())
        for a in episode_actions():
            env.step(a)
            obs = env.observed()
            if obs != g.observed:
                t = time.perf_counter()
                _ = g.update(obs)
                times.append(time.perf_counter() - t)
    return statistics.median(times), max(times)


def _one_more(domain, cache, full: Observed, reps: int) -> float:
    """Median seconds to add one newly observed entity to a full-scene grammar."""
    extra = Observed(full.entities | {"scrambled_eggs"}, full.contents)
    times = []
    for _ in range(reps * 20):
        g = cache.state("eggs", full)
        t = time.perf_counter()
        _ = g.update(extra)
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def _engines(text: str, reps: int) -> dict:
    from lark import Lark

    out = {"lark": timeit(lambda: Lark(text, parser="earley", lexer="dynamic"), repeat=max(1, reps // 3))}
    try:
        import llguidance
        from tokenizers import Tokenizer, decoders, models, pre_tokenizers, trainers
    except ImportError:
        return out
    tok = Tokenizer(models.BPE())
    tok.pre_tokenizer, tok.decoder = pre_tokenizers.ByteLevel(add_prefix_space=False), decoders.ByteLevel()
    tok.train_from_iterator(text.splitlines(), trainers.BpeTrainer(
        vocab_size=1000, special_tokens=["<eos>"], initial_alphabet=pre_tokenizers.ByteLevel.alphabet()))
    lltok = llguidance.LLTokenizer(tok.to_str(), eos_token=0)
    out["llguidance"] = timeit(lambda: llguidance.LLMatcher(lltok, llguidance.LLMatcher.grammar_from_lark(text)),
                               repeat=reps)
    return out


def run(quick: bool = False) -> list:
    """Measure and return report rows."""
    domain = load_domain(SPEC)
    reps = 3 if quick else 10
    index = build_index(domain)
    cache = GrammarCache(index)
    full = _full_state(domain)
    cache.base("eggs")
    new_state = timeit(lambda: cache.state("eggs", full).text, repeat=reps, number=20)
    scratch = timeit(lambda: StateGrammar(build_base(build_index(domain), "observed"), full).text, repeat=reps)
    update, worst = _per_update(domain, cache, reps)
    one = _one_more(domain, cache, full, reps)
    text = cache.state("eggs", full).text
    engines = _engines(text, reps)
    eng = ", ".join(f"{k} builds its parser in {v * 1e3:.1f} ms ({v / new_state:.0f}x)" for k, v in engines.items())
    return [
        ("grammar, new state (full scene, cached base)", new_state * 1e3, "ms", "< 5 ms",
         f"from scratch (index+base+terminals) {scratch * 1e3:.2f} ms = {scratch / new_state:.1f}x; "
         f"{len(text) / 1024:.0f} KiB of Lark"),
        ("grammar, update after one observation", one * 1e3, "ms", "< 1 ms",
         f"{new_state / one:.0f}x faster than a new state, {scratch / one:.0f}x faster than from scratch"),
        ("grammar, update per step (50-step replay)", update * 1e3, "ms", "< 1 ms",
         f"worst step {worst * 1e3:.3f} ms"),
        ("grammar, engine parser construction", min(engines.values()) * 1e3, "ms", "(reference)", eng),
    ]


if __name__ == "__main__":
    report(run())
