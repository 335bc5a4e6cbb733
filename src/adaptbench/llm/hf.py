"""The `transformers` backend: a model from a local directory, on CPU or GPU, batched generation with a
grammar per row (llguidance), and scoring that reads each prompt once (`scoring`).

    backend = TransformersBackend("models/tiny", device="cpu", dtype="float32")
"""

from __future__ import annotations

import gc
import time
from pathlib import Path

import torch
from transformers import (
    AutoModelForCausalLM,
    LogitsProcessorList,
    StoppingCriteria,
    StoppingCriteriaList,
)

from . import chat, lanes
from .backend import (
    Backend,
    Completion,
    canonical,
    check_device,
    context_limit,
    cut_at_stop,
    load_tokenizer,
)
from .constrained import GrammarProcessor, Matchers, closing_tokens, ll_tokenizer
from .cpu_kernels import BF16_WEIGHTS, pack_linears
from .decode import Picker, Row, Sessions, loop_supported, steps
from .sampling import RowSampler, SampleProcessor, generator, request_seed, sampling_config
from .scoring import read_prompt, score_after

DTYPES = {"auto": "auto", "float32": torch.float32, "bfloat16": torch.bfloat16, "float16": torch.float16,
          BF16_WEIGHTS: torch.float32}  # a float32 model whose decoder linear weights are bfloat16 (`cpu_kernels`)


def settle_heap() -> None:
    """Collect garbage once, then keep every object alive now (the model and its modules, the tokenizer,
    the compiled domain: ~480,000 objects with the tiny model) out of Python's cyclic collector's scans
    (`gc.freeze`, as vLLM does after loading a model). They live as long as the process. Without this,
    each full collection during a rollout walks all of them: 0.25 s, once every one or two 64-episode
    rollouts of 8 steps, a tenth of such a rollout's wall time on a GPU (measured with gc.callbacks)."""
    gc.collect()
    gc.freeze()


def load_model(path: str, dtype: str, device: str):
    """The model of a directory in `dtype` on `device`, for inference. On a CPU with bfloat16
    instructions a bfloat16 model's decoder linear layers are packed for oneDNN (the same numbers,
    faster: `cpu_kernels`), and `bfloat16-weights` loads float32 and packs only those layers' weights
    in bfloat16."""
    model = AutoModelForCausalLM.from_pretrained(path, dtype=DTYPES[dtype]).to(device).eval()
    packed = pack_linears(model, keep_dtype=dtype == BF16_WEIGHTS)
    if dtype == BF16_WEIGHTS and not packed:
        raise ValueError(f"--dtype {BF16_WEIGHTS} needs a CPU with bfloat16 instructions and a torch build with "
                         "oneDNN (use bfloat16 or float32 here)")
    return model


class RowStops(StoppingCriteria):
    """Ends each row at its own token limit or at the first of its stop strings."""

    def __init__(self, tokenizer, start: int, limits, stops):
        self.tokenizer, self.start, self.limits, self.stops = tokenizer, start, list(limits), list(stops)

    def __call__(self, input_ids: torch.LongTensor, scores, **kwargs) -> torch.BoolTensor:
        n = input_ids.shape[1] - self.start
        done = []
        for i, row in enumerate(input_ids):
            stop = n >= self.limits[i]
            if not stop and self.stops[i]:
                tail = self.tokenizer.decode(row[self.start:], skip_special_tokens=True)
                stop = any(s in tail for s in self.stops[i])
            done.append(stop)
        return torch.tensor(done, dtype=torch.bool, device=input_ids.device)


def _left_pad(rows, pad_id: int):
    width = max(len(r) for r in rows)
    ids = torch.full((len(rows), width), pad_id, dtype=torch.long)
    mask = torch.zeros((len(rows), width), dtype=torch.long)
    for i, r in enumerate(rows):
        if r:
            ids[i, width - len(r):] = torch.tensor(r, dtype=torch.long)
            mask[i, width - len(r):] = 1
    return ids, mask


class TransformersBackend(Backend):
    """A Hugging Face causal LM from a local directory. On the CPU, torch uses `threads` threads (1 by
    default: a small model gains nothing from more, and on a shared machine they contend). Greedy at
    `temperature` 0; above it, sampled under the run's sample seed `seed` (`llm.sampling`: a request with
    a `key` from its own generator, one without from the run's generator, seeded once here)."""

    name = "transformers"

    def __init__(self, model: str, device: str = "cpu", dtype: str = "auto", batch_size: int = 16,
                 temperature: float = 0.0, seed: int = 0, threads: int | None = 1, sessions: int | None = None):
        if not Path(model).is_dir():
            raise FileNotFoundError(f"--model {model}: not a directory (a model saved with save_pretrained; "
                                    "`adapt model init --out DIR` builds the tiny one)")
        if dtype not in DTYPES:
            raise ValueError(f"unknown dtype '{dtype}' (choose from: {', '.join(DTYPES)})")
        if threads and device == "cpu":
            torch.set_num_threads(threads)  # small models on shared CPUs: more threads only contend
        self.path, self.device, self.dtype = str(model), device, dtype
        self.batch_size, self.temperature, self.seed = batch_size, temperature, seed
        check_device(device)
        self.tokenizer = load_tokenizer(model, padding_side="left")
        self.model = load_model(model, dtype, device)
        self.context = context_limit(self.tokenizer, self.model.config)
        self.vocab = self.model.get_output_embeddings().weight.shape[0]
        self.lltok = ll_tokenizer(self.tokenizer, self.vocab)
        self.matchers = Matchers(self.lltok)
        self._copy = None  # the model in another precision, for `score(..., dtype)`
        self.pad_id = self.tokenizer.pad_token_id if self.tokenizer.pad_token_id is not None \
            else self.tokenizer.eos_token_id
        self.loop = loop_supported(self.model)
        self.prefill_together = device != "cpu"  # see decode.prefill_rows
        self.sessions = Sessions(2 * batch_size if sessions is None else sessions)
        self._generator = generator(seed, device)  # the run's: seeded once, for requests without a key
        settle_heap()

    def config(self) -> dict:
        """The model directory, device, dtype, sampling temperature and, when sampling, the sample seed."""
        return {"backend": self.name, "model": self.path, "device": self.device, "dtype": self.dtype,
                **sampling_config(self.temperature, self.seed)}

    def sampler(self, reqs: list) -> RowSampler:
        """Each request's temperature and generator (`llm.sampling`)."""
        temps = [self.temperature if r.temperature is None else r.temperature for r in reqs]
        gens = [None if t <= 0 else self._generator if r.key is None else
                generator(request_seed(self.seed, r.key), self.device) for r, t in zip(reqs, temps, strict=True)]
        return RowSampler(temps, gens)

    def encode(self, text: str) -> list:
        """Token ids of rendered text (no special tokens added: the chat template holds them)."""
        return chat.encode(self.tokenizer, text)

    def generate(self, requests) -> list:
        """Completions for the requests, `batch_size` rows per forward pass."""
        out = []
        for i in range(0, len(requests), self.batch_size):
            out += self._batch(list(requests[i:i + self.batch_size]))
        return out

    def release(self, session: str) -> None:
        """Forget a session's cached keys and values (its episode ended)."""
        self.sessions.drop(session)

    @torch.no_grad()
    def _batch(self, reqs: list) -> list:
        t0 = time.perf_counter()
        prompts = [self.encode(r.prompt) for r in reqs]
        if not self.loop:
            return self._batch_hf(reqs, prompts, self._processor(reqs), t0)
        rows = [Row(p, r.max_tokens, tuple(r.stop), getattr(r, "session", None)) for p, r in zip(prompts, reqs, strict=True)]
        parts = lanes.split(len(reqs), lanes.count(self.model, len(reqs)))  # each lane's rows: contiguous, in order
        lane_reqs, lane_rows = [[reqs[i] for i in p] for p in parts], [[rows[i] for i in p] for p in parts]
        procs = [self._processor(rq) for rq in lane_reqs]
        readings = lanes.run([steps(self.model, lr, self.sessions, Picker(proc, self.sampler(rq)), self._stopper(lr),
                                    self.pad_id, self.prefill_together, lane=k)
                              for k, (rq, lr, proc) in enumerate(zip(lane_reqs, lane_rows, procs, strict=True))])
        seconds, reading = time.perf_counter() - t0, max(readings)
        outs = [self._completion(r, row.tokens, len(row.prompt), proc, j, seconds, len(reqs), row.reused)
                for rq, lr, proc in zip(lane_reqs, lane_rows, procs, strict=True)
                for j, (r, row) in enumerate(zip(rq, lr, strict=True))]
        for o, row in zip(outs, rows, strict=True):
            o.stats["read_seconds"] = round(reading, 4)
            o.stats["forced_tokens"] = row.forced
        return outs

    def _processor(self, reqs: list):
        """The requests' grammar processor (None when none has a grammar)."""
        if not any(r.grammar is not None for r in reqs):
            return None
        eos = self.tokenizer.eos_token_id
        return GrammarProcessor(self.matchers, [r.grammar for r in reqs], eos, self.vocab,
                                [r.max_tokens for r in reqs], closing_tokens(self.tokenizer, eos))

    def _stopper(self, rows: list):
        eos = self.tokenizer.eos_token_id

        def stopped(i: int, row: Row) -> bool:
            if row.tokens[-1] == eos or len(row.tokens) >= row.max_tokens:
                return True
            if row.stop:
                tail = self.tokenizer.decode(row.tokens, skip_special_tokens=True)
                return any(s and s in tail for s in row.stop)
            return False

        return stopped

    def _batch_hf(self, reqs: list, prompts: list, proc, t0: float) -> list:
        """`model.generate` (models whose cache this loop does not handle, e.g. sliding-window layers)."""
        ids, mask = _left_pad(prompts, self.pad_id)
        ids, mask = ids.to(self.device), mask.to(self.device)
        eos = self.tokenizer.eos_token_id
        stops = RowStops(self.tokenizer, ids.shape[1], [r.max_tokens for r in reqs], [r.stop for r in reqs])
        sampler = self.sampler(reqs)  # each row drawn with its own generator, after the grammar's mask
        processors = ([proc] if proc else []) + ([] if sampler.greedy else [SampleProcessor(sampler)])
        gen = self.model.generate(
            input_ids=ids, attention_mask=mask, max_new_tokens=max(r.max_tokens for r in reqs),
            logits_processor=LogitsProcessorList(processors),
            stopping_criteria=StoppingCriteriaList([stops]), do_sample=False,
            temperature=None, top_p=None, top_k=None, pad_token_id=self.pad_id, eos_token_id=eos)
        seconds = time.perf_counter() - t0
        return [self._completion(r, gen[i, ids.shape[1]:].tolist(), len(prompts[i]), proc, i, seconds, len(reqs))
                for i, r in enumerate(reqs)]

    def _generated(self, tokens: list) -> list:
        """A row's generated ids: up to and including EOS, else without the padding `model.generate`
        puts after a row that stopped early."""
        eos = self.tokenizer.eos_token_id
        if eos in tokens:
            return tokens[:tokens.index(eos) + 1]
        end = len(tokens)
        while end and tokens[end - 1] == self.pad_id:
            end -= 1
        return tokens[:end]

    def _completion(self, req, tokens: list, n_prompt: int, proc, row: int, seconds: float, batch: int,
                    reused: int | None = None):
        tokens = self._generated(tokens)
        if proc is not None and req.grammar is not None:
            proc.finish(row, tokens)
        text = cut_at_stop(self.tokenizer.decode(tokens, skip_special_tokens=True), req.stop)
        accepted = None if req.grammar is None else proc.accepted(row)
        stats = {"seconds": round(seconds, 4), "batch": batch, "canonical": canonical(self.tokenizer, tokens)}
        if reused is not None:
            stats["cached_tokens"] = reused
        if proc is not None:
            stats["mask_seconds"] = round(proc.mask_seconds, 4)
        return Completion(text, n_prompt, len(tokens), accepted, stats, tuple(tokens))

    def score_dtype(self, dtype: str | None = None) -> str:
        """The precision `score(..., dtype)` runs the model in: `dtype`, or the model's own."""
        if dtype:
            return dtype
        return BF16_WEIGHTS if self.dtype == BF16_WEIGHTS else str(self.model.dtype).removeprefix("torch.")

    def _scorer(self, dtype: str | None):
        """The model to score with: this one, or for another `dtype` the model directory loaded again in
        that precision (the checkpoint's weights, not this model's rounded ones; loaded once and kept: a
        float32 copy beside a bfloat16 model takes twice its memory)."""
        if dtype is None or dtype == self.dtype or (DTYPES.get(dtype, dtype) == self.model.dtype
                                                    and self.dtype != BF16_WEIGHTS):
            return self.model
        if dtype not in DTYPES or dtype == "auto":
            raise ValueError(f"unknown scoring dtype '{dtype}' (choose from: float32, bfloat16, float16)")
        if self._copy is None or self._copy[0] != dtype:
            self._copy = (dtype, load_model(self.path, dtype, self.device))
        return self._copy[1]

    @torch.no_grad()
    def score_ids(self, groups, dtype: str | None = None) -> list:
        """Per-token log-probabilities of each group's completions (`Backend.score_ids`): a group's
        prompt is read once; its completions are read after its keys and values, `batch_size` per pass
        (`scoring`). `dtype` ("float32"): run the model in that precision (`score_dtype`)."""
        model = self._scorer(dtype)
        out = []
        for prompt, conts in groups:
            conts = [list(c) for c in conts]
            if not conts:
                out.append([])
                continue
            first, layers = read_prompt(model, list(prompt))
            got = []
            for i in range(0, len(conts), self.batch_size):
                got += score_after(model, first, layers, len(prompt), conts[i:i + self.batch_size], self.pad_id)
            out.append(got)
        return out
