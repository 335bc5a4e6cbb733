"""Constrained decoding engines side by side on the tiny model (CPU), one run, the same prompts and the
same state grammar, one generation at a time (greedy, `--tokens` new tokens at most):

- unconstrained generation (the `transformers` backend's loop, `llm/decode.py`, no grammar), each
  request stopped after as many tokens as its constrained completion took;
- ours: the `transformers` backend's loop with llguidance masks (`llm/constrained.py`);
- the same two on `model.generate` (our llguidance logits processor there): the loop every competitor
  runs in, so that "ours / engine" compares grammar engines, not generation loops;
- transformers-CFG (the authors' release's choice; pip `transformers-cfg`), fed the grammar converted
  to its EBNF by `lark_to_ebnf`;
- outlines 1.x's default CFG path (`outlines.types.CFG` on the Lark text; its backend is llguidance).

    python bench/bench_decoding.py [--model DIR] [--n 24] [--tokens 24] [--device cuda] [--dtype bfloat16]

transformers-CFG and outlines are not dependencies of the project: install them for this benchmark
only (`pip install transformers-cfg outlines`). A competitor that is not installed, or that fails
under the installed transformers, is skipped and the reason printed. Each row also says how many
completions the simulator's parser accepts. Figures go to docs/llm.md.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import re
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.bench_llm import _requests  # noqa: E402
from bench.common import SPEC  # noqa: E402

_TOKEN = re.compile(r'\s*(?:(?P<str>"(?:[^"\\]|\\.)*")|(?P<re>/(?:[^/\\]|\\.)+/)|(?P<name>[A-Za-z_][A-Za-z0-9_]*)'
                    r"|(?P<op>[|()*+?]))")


def _ebnf_name(name: str) -> str:
    # Lark terminals are upper case, rules lower case: keep them apart (VERB vs verb) in EBNF.
    return ("t-" if name.isupper() or name[0].isupper() else "r-") + name.lower().replace("_", "-")


def _regex_to_ebnf(rx: str) -> str:
    """A Lark regex body of character classes, literal characters and `*`/`+`/`?` as EBNF."""
    out, i = [], 0
    while i < len(rx):
        c = rx[i]
        if c == "[":
            j = i + 1
            while rx[j] != "]" or rx[j - 1] == "\\":
                j += 1
            out.append(rx[i:j + 1])
            i = j + 1
        elif c in "*+?":
            out[-1] += c
            i += 1
        elif c in "()|.{}^$":
            raise ValueError(f"regex /{rx}/: '{c}' is not handled by this converter")
        else:
            if c == "\\":
                c, i = rx[i:i + 2], i + 1
            out.append('"' + ('\\"' if c == '"' else c) + '"')
            i += 1
    return "(" + " ".join(out) + ")"


def _lark_rules(lark_text: str) -> list:
    """[name, expression] of each rule or terminal, continuation lines joined, comments dropped."""
    rules, current = [], None
    for line in lark_text.splitlines():
        if not line.strip() or line.lstrip().startswith("//"):
            continue
        m = re.match(r"^([A-Za-z_][A-Za-z0-9_]*)\s*:(.*)$", line)
        if m:
            current = [m.group(1), m.group(2)]
            rules.append(current)
        elif line.startswith((" ", "\t")) and current is not None:
            current[1] += " " + line.strip()
        else:
            raise ValueError(f"line not handled: {line[:80]}")
    return rules


def _ebnf_expr(name: str, expr: str) -> str:
    parts, pos, end = [], 0, len(expr.rstrip())
    while pos < end:
        t = _TOKEN.match(expr, pos)
        if t is None:
            raise ValueError(f"rule {name}: cannot read {expr[pos:pos + 30]!r}")
        pos = t.end()
        if t.group("re"):
            parts.append(_regex_to_ebnf(t.group("re")[1:-1]))
        elif t.group("name"):
            parts.append(_ebnf_name(t.group("name")))
        else:
            parts.append(t.group("str") or t.group("op"))
    return " ".join(parts)


def lark_to_ebnf(lark_text: str) -> str:
    """The adaptbench Lark grammar (rules and terminals of strings, names, groups, alternatives and
    simple regexes) in transformers-CFG's EBNF (`root ::= ...`)."""
    out = ["root ::= r-start"]
    out += [f"{_ebnf_name(name)} ::= {_ebnf_expr(name, expr)}" for name, expr in _lark_rules(lark_text)]
    return "\n".join(out) + "\n"


class Engine:
    """One decoding engine: `generate(request) -> (text, new tokens)`."""

    def __init__(self, name: str, generate):
        self.name, self.generate = name, generate
        self.compile_seconds = 0.0  # grammar set-up inside `generate`, left out of tokens/s


def _free(req, lengths: dict):
    """The request without its grammar, limited to the tokens the grammar's completion took (an action
    ends after ~9 tokens; a free row running to the limit would spread the call's fixed cost, reading
    the prompt, over more tokens and flatter the unconstrained rate)."""
    return type(req)(req.prompt, None, (), lengths.get(req.prompt, req.max_tokens))


def _ours(backend, constrained: bool, lengths: dict):
    def gen(req):
        r = req if constrained else _free(req, lengths)
        out = backend.generate([r])[0]
        return out.text, out.tokens
    return Engine("llguidance (ours)" if constrained else "unconstrained", gen)


def _ours_on_generate(backend, constrained: bool, lengths: dict):
    from adaptbench.llm.constrained import GrammarProcessor, closing_tokens

    eos = backend.tokenizer.eos_token_id

    def gen(req):
        req = req if constrained else _free(req, lengths)
        procs = [GrammarProcessor(backend.matchers, [req.grammar], eos, backend.vocab, [req.max_tokens],
                                  closing_tokens(backend.tokenizer, eos))] if constrained else []
        return _hf_generate(backend, req, procs)
    name = "llguidance processor, model.generate" if constrained else "unconstrained, model.generate"
    return Engine(name, gen)


def _transformers_cfg(backend):
    from transformers_cfg.generation.logits_process import GrammarConstrainedLogitsProcessor
    from transformers_cfg.grammar_utils import IncrementalGrammarConstraint

    tok = _gpt2_view(backend)
    ebnf: dict = {}
    engine = Engine("transformers-CFG", None)
    engine.compile_seconds = 0.0

    def gen(req):
        # a constraint holds its sequence's parse state: one per generation (compiling is timed apart)
        t = time.perf_counter()
        grammar = ebnf.setdefault(req.grammar, lark_to_ebnf(req.grammar))
        proc = GrammarConstrainedLogitsProcessor(IncrementalGrammarConstraint(grammar, "root", tok))
        engine.compile_seconds += time.perf_counter() - t
        return _hf_generate(backend, req, [proc])
    engine.generate = gen
    return engine


def _gpt2_view(backend):
    """The tiny model's tokenizer loaded as `GPT2TokenizerFast` (same byte-level BPE, same ids):
    transformers-CFG 0.2.7 dispatches on the tokenizer's class and rejects transformers 5.x's
    generic `TokenizersBackend` ("NotImplementedError: Tokenizer not supported: TokenizersBackend")."""
    import transformers_cfg.tokenization.middle.ByteProxyMapping as proxy
    from transformers import GPT2TokenizerFast

    tok = GPT2TokenizerFast.from_pretrained(backend.path, unk_token="<|pad|>")
    if tok.get_vocab() != backend.tokenizer.get_vocab():
        raise ValueError("the GPT-2 view of the tokenizer differs from the model's tokenizer")
    # It then reloads the tokenizer "slow" by name and, finding no `byte_encoder` (gone in 5.x), downloads
    # the hub's `gpt2` for GPT-2's byte-to-unicode table: hand it ours, with that table, instead.
    tok.byte_encoder = _bytes_to_unicode()
    tok.byte_decoder = {c: b for b, c in tok.byte_encoder.items()}

    class _Auto:
        @staticmethod
        def from_pretrained(*_a, **_k):
            return tok
    proxy.AutoTokenizer = _Auto
    return tok


def _bytes_to_unicode() -> dict:
    """GPT-2's byte-level BPE table: byte -> printable character."""
    bs = [*range(ord("!"), ord("~") + 1), *range(ord("¡"), ord("¬") + 1), *range(ord("®"), ord("ÿ") + 1)]
    cs, n = bs[:], 0
    for b in range(256):
        if b not in bs:
            bs.append(b)
            cs.append(256 + n)
            n += 1
    return dict(zip(bs, map(chr, cs), strict=True))


def _hf_generate(backend, req, processors):
    import torch
    from transformers import LogitsProcessorList

    ids = torch.tensor([backend.encode(req.prompt)], device=backend.model.device)
    with torch.no_grad():
        gen = backend.model.generate(input_ids=ids, attention_mask=torch.ones_like(ids), max_new_tokens=req.max_tokens,
                                     logits_processor=LogitsProcessorList(processors), do_sample=False,
                                     pad_token_id=backend.pad_id, eos_token_id=backend.tokenizer.eos_token_id)
    new = gen[0, ids.shape[1]:].tolist()
    eos = backend.tokenizer.eos_token_id
    new = new[:new.index(eos) + 1] if eos in new else new
    return backend.tokenizer.decode(new, skip_special_tokens=True), len(new)


def _outlines(backend):
    os.environ.setdefault("TORCHDYNAMO_DISABLE", "1")  # its mask kernel is torch.compile'd: ~30 s cold on CPU
    import outlines
    from outlines.types import CFG

    model = outlines.from_transformers(backend.model, backend.tokenizer)
    generators: dict = {}

    def gen(req):
        if req.grammar not in generators:
            generators[req.grammar] = outlines.Generator(model, CFG(req.grammar))
        text = generators[req.grammar](req.prompt, max_new_tokens=req.max_tokens, do_sample=False)
        return text, len(backend.encode(text))
    return Engine("outlines (CFG)", gen)


COMPETITORS = {"transformers-CFG": ("transformers_cfg", _transformers_cfg), "outlines (CFG)": ("outlines", _outlines)}


def engines(backend, lengths: dict) -> tuple:
    """The engines that could be built, and (name, reason) for those skipped (`lengths`: by prompt, the
    tokens of its constrained completion, where the unconstrained rows stop)."""
    built, skipped = [_ours(backend, False, lengths), _ours(backend, True, lengths),
                      _ours_on_generate(backend, False, lengths), _ours_on_generate(backend, True, lengths)], []
    for name, (module, make) in COMPETITORS.items():
        if importlib.util.find_spec(module) is None:
            skipped.append((name, f"not installed (pip install {module.replace('_', '-')})"))
            continue
        try:
            built.append(make(backend))
        except Exception as exc:  # noqa: BLE001 - a competitor failing under transformers 5.x is a result
            skipped.append((name, f"{type(exc).__name__}: {exc}"))
    return built, skipped


def measure(engine, reqs, parser) -> dict:
    """Tokens/s over the requests (after one warm-up call), and how many completions parse."""
    engine.generate(reqs[0])
    engine.compile_seconds = 0.0
    tokens, parsed, t = 0, 0, time.perf_counter()
    for r in reqs:
        text, n = engine.generate(r)
        tokens += n
        parsed += parser.parse(text) is not None
    wall = time.perf_counter() - t
    return {"tok_s": tokens / (wall - engine.compile_seconds), "parsed": parsed, "n": len(reqs), "tokens": tokens,
            "compile_s": engine.compile_seconds / len(reqs)}


def run(model: str | None, n: int, max_tokens: int, device: str = "cpu", dtype: str = "auto") -> tuple:
    """(rows of results, skipped competitors)."""
    from adaptbench.compiler import load_domain
    from adaptbench.llm.hf import TransformersBackend
    from adaptbench.llm.tiny import init_tiny
    from adaptbench.runtime.index import runtime_index

    domain = load_domain(SPEC)
    if model is None:
        model = str(init_tiny(domain, Path(tempfile.mkdtemp()) / "tiny"))
    backend = TransformersBackend(model, device=device, dtype=dtype, batch_size=1)
    reqs = [type(r)(r.prompt, r.grammar, (), max_tokens) for r in _requests(domain, backend, n, True)]
    parser = runtime_index(domain).parser
    lengths = {r.prompt: max(1, c.tokens) for r, c in zip(reqs, backend.generate(reqs), strict=True)}
    built, skipped = engines(backend, lengths)
    rows = []
    for e in built:
        try:
            rows.append((e.name, measure(e, reqs, parser)))
        except Exception as exc:  # noqa: BLE001
            skipped.append((e.name, f"failed while generating: {type(exc).__name__}: {str(exc)[:300]}"))
    return rows, skipped


def main() -> int:
    """Run and print."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", help="model directory (default: build the tiny model in a temp dir)")
    p.add_argument("--n", type=int, default=24, help="generations per engine (default 24)")
    p.add_argument("--tokens", type=int, default=24, help="max new tokens per generation (default 24)")
    p.add_argument("--device", default="cpu", help="cpu (default), cuda, ...")
    p.add_argument("--dtype", default="auto", help="auto (default), float32, bfloat16, float16")
    args = p.parse_args()
    rows, skipped = run(args.model, args.n, args.tokens, args.device, args.dtype)
    base = dict(rows).get("unconstrained", {}).get("tok_s")
    ours = dict(rows).get("llguidance (ours)", {}).get("tok_s")
    print(f"{'engine':<38} {'tok/s':>8} {'/ unconstr.':>11} {'ours / it':>10} {'parsed':>8} {'set-up s/gen':>12}")
    for name, r in rows:
        print(f"{name:<38} {r['tok_s']:>8.1f} {r['tok_s'] / base:>11.2f} {ours / r['tok_s']:>10.2f} "
              f"{r['parsed']:>4}/{r['n']} {r['compile_s']:>12.3f}")
    for name, why in skipped:
        print(f"skipped {name}: {why}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
