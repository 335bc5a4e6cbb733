"""Grammar-constrained decoding for transformers, backed by llguidance.

    matchers = Matchers(ll_tokenizer(tokenizer, vocab_size))   # built once per (tokenizer, vocab)
    proc = GrammarProcessor(matchers, [grammar_a, None, grammar_b], eos_id, vocab_size)
    model.generate(..., logits_processor=LogitsProcessorList([proc]))

One `LLMatcher` per batch row, each with its own Lark grammar (None: that row is unconstrained). Each
step the processor feeds every running row's last token to its matcher, fills the rows' token bitmasks
in parallel (`LLExecutor`) and masks the logits. The bitmask is applied with plain tensor operations
(llguidance's helper is `torch.compile`d: ~30 s on the first CPU call). A row is finished once it
emits EOS; its later (padding) tokens are not fed to the matcher.
"""

from __future__ import annotations

import os
import time

import llguidance
import llguidance.hf
import numpy as np
import torch
from llguidance.torch import allocate_token_bitmask, fill_next_token_bitmask, fill_next_token_bitmask_par
from transformers import LogitsProcessor

_EXECUTOR: list = []  # the process's llguidance executor, made on first use
os.register_at_fork(after_in_child=_EXECUTOR.clear)  # its threads do not survive a fork: a child makes its own
MATCHER_CACHE = 256


def ll_tokenizer(tokenizer, vocab_size: int | None = None) -> llguidance.LLTokenizer:
    """The llguidance tokenizer of a Hugging Face fast tokenizer (with `vocab_size` the model's
    logits width when it differs from the tokenizer's), built once and kept on the tokenizer object."""
    built = tokenizer.__dict__.setdefault("_adapt_lltok", {})
    if vocab_size not in built:
        built[vocab_size] = llguidance.hf.from_tokenizer(tokenizer, n_vocab=vocab_size)
    return built[vocab_size]


class Matchers:
    """Pristine matchers by grammar text for one llguidance tokenizer (bounded LRU); `get` returns a
    copy. Building a matcher from a 37 KiB state grammar costs ~15 ms, copying one ~1 µs, and an
    episode's grammar changes only when it observes more."""

    def __init__(self, lltok, maxsize: int = MATCHER_CACHE):
        from ..runtime.tables import LRU

        self.lltok = lltok
        self._lru = LRU(maxsize)

    def get(self, grammar: str) -> llguidance.LLMatcher:
        """A fresh matcher for the grammar."""
        return self._lru.get_or_build(grammar, lambda: llguidance.LLMatcher(self.lltok, grammar, log_level=0)).deep_copy()


def executor() -> llguidance.LLExecutor:
    """The process's llguidance executor (computes the rows' masks in parallel)."""
    if not _EXECUTOR:
        spare = (os.cpu_count() or 2) - torch.get_num_threads()  # cores the model's threads leave free
        _EXECUTOR.append(llguidance.LLExecutor(num_threads=max(1, min(32, spare))))
    return _EXECUTOR[0]


def grammar_error(lltok, grammar: str) -> str:
    """Why llguidance rejects a Lark grammar ("" when it accepts it)."""
    return llguidance.LLMatcher.validate_grammar(grammar, lltok)


_BITS = {"cpu": torch.arange(32, dtype=torch.int32)}  # by device


def _bits(device) -> torch.Tensor:
    key = str(device)
    if key not in _BITS:
        _BITS[key] = torch.arange(32, dtype=torch.int32, device=device)
    return _BITS[key]


def unpack_bits(words: torch.Tensor, vocab: int) -> torch.Tensor:
    """Allowed-token booleans [rows, vocab] from llguidance bitmask words [rows, n] (int32; bit i of word
    w = token 32 w + i), on the words' device; tokens past the mask are not allowed."""
    table = ((words.unsqueeze(-1) >> _bits(words.device)) & 1).bool().reshape(words.shape[0], -1)
    if table.shape[1] < vocab:
        table = torch.nn.functional.pad(table, (0, vocab - table.shape[1]), value=False)
    return table[:, :vocab]


def apply_bitmask(logits: torch.Tensor, bitmask: torch.Tensor, rows) -> None:
    """Set to -inf the logits of tokens not allowed by `bitmask` (int32 words, bit i of word w = token
    32 w + i) in the given rows, in place."""
    if not rows:
        return
    idx = torch.tensor(rows, dtype=torch.long)
    allowed = unpack_bits(bitmask[idx], logits.shape[1]).to(logits.device)
    idx = idx.to(logits.device)
    logits[idx] = logits[idx].masked_fill(~allowed, float("-inf"))


def closing_tokens(tokenizer, eos_id: int) -> torch.Tensor:
    """Token ids that can end an action: EOS and every token holding a double quote (the end of a
    quoted free-text question). Cached on the tokenizer object."""
    hit = getattr(tokenizer, "_adapt_closing", None)
    if hit is None:
        vocab = tokenizer.get_vocab()
        ids = [i for t, i in vocab.items() if '"' in tokenizer.convert_tokens_to_string([t])]
        hit = torch.tensor(sorted({*ids, eos_id}), dtype=torch.long)
        tokenizer._adapt_closing = hit
    return hit


class GrammarProcessor(LogitsProcessor):
    """A transformers logits processor holding one llguidance matcher per batch row.

    Free text is bounded by the token limit, not by the grammar (docs/grammar.md), so a row about to
    reach its limit (`limits`) is steered to close: in its last `reserve` steps only tokens that end
    an action (`closing`: EOS, a closing quote) are kept when the grammar allows any of them. Every
    completion then parses, however long the model would have rambled. The reserve is 4 tokens: a
    byte-level token can open a character of up to 4 UTF-8 bytes whose other bytes the grammar then
    forces, up to 3 tokens in which no quote can close."""

    def __init__(self, matchers: Matchers, grammars, eos_id: int, vocab_size: int, limits=None, closing=None,
                 reserve: int = 4):
        self.matchers = [None if g is None else matchers.get(g) for g in grammars]
        for i, m in enumerate(self.matchers):
            if m is not None and m.is_error():
                raise ValueError(f"grammar of row {i} rejected by llguidance: {m.get_error()}")
        self.eos_id = eos_id
        self.bitmask = allocate_token_bitmask(len(grammars), vocab_size)
        self.vocab = vocab_size
        self.limits = list(limits) if limits is not None else [None] * len(grammars)
        self.closing, self.reserve = closing, reserve
        self.steps = 0
        self.consumed = [0] * len(grammars)
        self.started = False
        self.finished = [False] * len(grammars)
        self.errors = [""] * len(grammars)
        self.mask_seconds = 0.0
        self.masked_steps = 0

    def _consume(self, input_ids: torch.Tensor) -> None:
        last = input_ids[:, -1].tolist()
        for i in range(len(self.matchers)):
            if self.finished[i]:
                continue
            if last[i] == self.eos_id:
                self.finished[i] = True
            self._feed(i, last[i])

    def _feed(self, i: int, token: int) -> None:
        m = self.matchers[i]
        self.consumed[i] += 1
        if m is not None and not self.errors[i] and not m.consume_token(token):
            self.errors[i] = m.get_error() or "token rejected"

    def finish(self, row: int, tokens: list) -> None:
        """Feed a row's generated tokens the processor has not seen (the last one, when generation
        stopped at the limit) so that `accepted` judges the whole completion."""
        for t in tokens[self.consumed[row]:]:
            if self.finished[row]:
                break
            if t == self.eos_id:
                self.finished[row] = True
            self._feed(row, t)

    def __call__(self, input_ids: torch.Tensor, scores: torch.Tensor) -> torch.Tensor:
        if self.started:
            self._consume(input_ids)
        self.started = True
        t0 = time.perf_counter()
        live = [(m, i) for i, m in enumerate(self.matchers)
                if m is not None and not self.finished[i] and not self.errors[i]]
        if live:
            fill_next_token_bitmask_par(executor(), live, self.bitmask)
            apply_bitmask(scores, self.bitmask, [i for _, i in live])
            self._close([i for _, i in live], scores)
            self.masked_steps += 1
        self.steps += 1
        self.mask_seconds += time.perf_counter() - t0
        return scores

    def _near_limit(self, row: int, step) -> bool:
        """Whether the row is in its last `reserve` tokens (`step`: the index of the token about to be
        chosen, one for all rows or by row)."""
        limit = self.limits[row]
        return limit is not None and limit - (step[row] if isinstance(step, dict) else step) <= self.reserve

    def _close(self, rows, scores: torch.Tensor, step=None, at=None) -> None:
        """Keep only the closing tokens of the rows near their limit whose masks allow one (the rows'
        logits in `scores` at `at[i]`, else at i): one batched operation, no transfer to the host."""
        if self.closing is None:
            return
        step = self.steps if step is None else step
        near = [i if at is None else at[i] for i in rows if self._near_limit(i, step)]
        if not near:
            return
        idx = torch.tensor(near, dtype=torch.long, device=scores.device)
        keep = self.closing.to(scores.device)
        sub = scores[idx]
        closing = sub[:, keep]
        can = (closing > float("-inf")).any(dim=1, keepdim=True)
        only = torch.full_like(sub, float("-inf"))
        only[:, keep] = closing
        scores[idx] = torch.where(can, only, sub)

    # The generation loop's interface (`decode.decode`): rows are named by their index in the request
    # list, logits rows by their place among the rows still running.

    def feed(self, rows, tokens) -> None:
        """Feed each row its newest token (the constrained rows' in one call that drops the GIL)."""
        batch = []
        for i, t in zip(rows, tokens, strict=True):
            if self.finished[i]:
                continue
            self.finished[i] = t == self.eos_id
            self.consumed[i] += 1
            if self.matchers[i] is not None and not self.errors[i]:
                batch.append((i, t))
        if len(batch) == 1:  # one row: no hand-over to the executor's threads
            ok = [self.matchers[batch[0][0]].consume_token(batch[0][1])]
        else:
            ok = executor().consume_token_par([(self.matchers[i], t) for i, t in batch]) if batch else []
        for (i, _), good in zip(batch, ok, strict=True):
            if not good:
                self.errors[i] = self.matchers[i].get_error() or "token rejected"

    def live(self, rows) -> list:
        """The rows still constrained (a grammar, not finished, no error)."""
        return [i for i in rows if self.matchers[i] is not None and not self.finished[i] and not self.errors[i]]

    def fill(self, rows) -> list:
        """Compute the next-token masks of the rows still constrained; returns those rows."""
        live = [(self.matchers[i], i) for i in self.live(rows)]
        if len(live) == 1:  # one row: no hand-over to the executor's threads
            fill_next_token_bitmask(live[0][0], self.bitmask, live[0][1])
        elif live:
            fill_next_token_bitmask_par(executor(), live, self.bitmask)
        return [i for _, i in live]

    def mask(self, logits: torch.Tensor, rows, live, step) -> None:
        """Mask `logits` (row k is request row `rows[k]`) with the masks `fill` computed for `live`, and
        steer rows near their token limit to close (`step`: the index of the token being chosen, one
        for all rows or a dict by row)."""
        if not live:
            return
        vocab = logits.shape[1]
        same = len(live) == len(rows) and list(live) == list(rows)
        words = self._words(logits.device)
        if not (same and len(rows) == self.bitmask.shape[0]):
            words = words[torch.tensor(live, dtype=torch.long, device=words.device)]
        forbidden = ~unpack_bits(words, vocab)  # unpacked where the logits are
        if same:  # every row constrained, in order: mask in place
            logits.masked_fill_(forbidden, float("-inf"))
        else:
            at = {i: k for k, i in enumerate(rows)}
            idx = torch.tensor([at[i] for i in live], dtype=torch.long, device=logits.device)
            logits[idx] = logits[idx].masked_fill(forbidden, float("-inf"))
        if self.closing is not None and any(self._near_limit(i, step) for i in live):
            self._close(live, logits, step, {i: k for k, i in enumerate(rows)})
        self.masked_steps += 1

    def _words(self, device) -> torch.Tensor:
        """The bitmask on `device`: on a GPU copied whole from pinned memory without waiting (the next
        `fill` comes after the picked tokens reach the host, so after this copy)."""
        if device.type == "cpu":
            return self.bitmask
        if not self.bitmask.is_pinned():
            self.bitmask = self.bitmask.pin_memory()
        return self.bitmask.to(device, non_blocking=True)

    def forced(self, live) -> dict:
        """{row: token} for the rows of `live` (rows `fill` just computed) whose mask allows exactly one
        token: the grammar leaves no choice, so the token is taken without asking the model (llguidance
        calls it fast-forwarding). Choosing among one allowed token, greedy or sampled, gives it anyway:
        only the model's forward pass for it is saved."""
        if not live:
            return {}
        words = self.bitmask.numpy()[live].view(np.uint32)
        out = {}
        for k in np.flatnonzero((words != 0).sum(axis=1) == 1):  # one word with a bit set...
            at = int(np.flatnonzero(words[k])[0])
            bits = int(words[k, at])
            token = 32 * at + bits.bit_length() - 1
            if bits & (bits - 1) == 0 and token < self.vocab:  # ...and one bit in it, a token of the model
                out[live[k]] = token
        return out

    def accepted(self, row: int) -> bool:
        """Whether row `row`'s matcher ended in an accepting state (True for unconstrained rows)."""
        m = self.matchers[row]
        return m is None or (not self.errors[row] and m.is_accepting())
