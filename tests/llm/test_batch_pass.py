"""The GPU's decoding passes (`llm.batch_pass`), checked on the CPU: the lean batched pass equals the
model's forward (padding, a cache, several new tokens, grouped heads), and rollouts through it and
through the key/value pool of the graphed one-token pass (run eagerly off CUDA) take the same actions
as the model's forward, with sessions keeping copies, never the pool."""

from __future__ import annotations

import os

import pytest

from .conftest import SKIP_MODELS
from .test_decode import _actions, _sharp

pytestmark = [SKIP_MODELS]
DEVICE = os.environ.get("ADAPT_TEST_DEVICE", "cpu")  # cuda: the same checks on a GPU, graphs captured


def test_the_lean_pass_equals_the_model_forward_over_padding_a_cache_and_grouped_heads(tiny):
    """Three rows, left padding in the cache and padding among the new tokens: the last position's
    logits through `forward` (heads folded, one additive mask, stacked projections) equal the model's."""
    import torch
    from transformers import DynamicCache

    from adaptbench.llm.batch_pass import attention_bias, forward
    from adaptbench.llm.decode import _head, cache_arg
    from adaptbench.llm.kv_buffer import BufferLayer

    model = _sharp(tiny, device=DEVICE).model
    assert model.config.num_key_value_heads < model.config.num_attention_heads
    g = torch.Generator().manual_seed(0)
    ids = torch.randint(0, 3000, (3, 40), generator=g)
    mask = torch.ones(3, 40, dtype=torch.long)
    mask[1, :8], mask[2, 30:33] = 0, 0
    pos = (mask.cumsum(-1) - 1).clamp(min=0)
    ids, mask, pos = ids.to(DEVICE), mask.to(DEVICE), pos.to(DEVICE)
    with torch.no_grad():
        cache = DynamicCache(config=model.config)
        model(input_ids=ids[:, :30], attention_mask=mask[:, :30], position_ids=pos[:, :30], **cache_arg(model, cache))
        want = model(input_ids=ids[:, 30:], attention_mask=mask, position_ids=pos[:, 30:],
                     cache_position=torch.arange(30, 40, device=DEVICE), **cache_arg(model, cache)).logits[:, -1]
        layers = [BufferLayer(room=10) for _ in model.model.layers]
        forward(model, layers, ids[:, :30], pos[:, :30], attention_bias(mask[:, :30], 30, model.dtype))
        hidden = forward(model, layers, ids[:, 30:], pos[:, 30:], attention_bias(mask, 10, model.dtype))
        got = _head(model, hidden, None)
    assert torch.allclose(got, want, atol=1e-4)


def test_the_attention_bias_is_causal_among_new_tokens_and_hides_padding():
    """0 where a query may look (a real cached position, or a new token not after it), the minimum
    elsewhere; rows 16-element aligned in memory."""
    import torch

    from adaptbench.llm.batch_pass import attention_bias

    mask = torch.tensor([[0, 1, 1, 1, 1], [1, 1, 1, 0, 1]])
    bias = attention_bias(mask, 2, torch.float32)
    allowed = (bias == 0)[:, 0]
    assert allowed[0].tolist() == [[False, True, True, True, False], [False, True, True, True, True]]
    assert allowed[1].tolist() == [[True, True, True, False, False], [True, True, True, False, True]]
    assert bias.stride(2) % 16 == 0


@pytest.mark.parametrize("mode", ["lean", "graphs"])
@pytest.mark.parametrize("batch,ride", [(1, False), (5, True), (5, False)])
def test_rollouts_through_the_gpu_passes_act_as_the_model_forward_does(domain, tiny, mode, batch, ride, monkeypatch):
    """Planner rollouts (greedy, under the grammar; one row, several with stopped rows riding and with
    compaction) take the same actions through the lean pass and through the pool's graphed passes (one
    token, and a row's forced tokens together) as through the model's forward; the pool's passes ran."""
    from adaptbench.llm import batch_pass, decode

    if ride:
        monkeypatch.setattr(decode, "COMPACT_BYTES", 0)
    ours, plain = _sharp(tiny, device=DEVICE), _sharp(tiny, device=DEVICE)
    batch_pass.set_mode(ours.model, mode)
    ours.model.__dict__["_adapt_lean"] = False  # the CPU's one-row pass would take single rows first
    batch_pass.set_mode(plain.model, "hf")
    steps = []
    real = batch_pass.DecodeGraphs.step

    def counted(self, *args):
        steps.append(max(len(t) for t in args[1]))  # tokens a row reads in the pass
        return real(self, *args)

    monkeypatch.setattr(batch_pass.DecodeGraphs, "step", counted)
    assert _actions(domain, ours, batch) == _actions(domain, plain, batch)
    assert bool(steps) == (mode == "graphs")
    if steps:
        assert min(steps) == 1 and max(steps) > 1  # one-token passes, and passes over forced tokens


def test_sessions_keep_copies_of_the_pool_and_a_larger_batch_gets_a_larger_pool(domain, tiny):
    """What a session keeps after a pooled decode is its own buffer, not a view of the pool (the pool
    is the next call's); a call with more rows than the pool holds makes a larger one."""
    from adaptbench.llm import batch_pass
    from adaptbench.llm.backend import Request
    from adaptbench.llm.kv_buffer import PackedRow

    from .test_decode import _grammar, _prompts

    b = _sharp(tiny, batch_size=8, device=DEVICE)
    batch_pass.set_mode(b.model, "graphs")
    b.model.__dict__["_adapt_lean"] = False
    g = _grammar(domain)
    prompts = _prompts(domain, b, 3)
    b.generate([Request(prompts[0], g, (), 12, session="a")])
    pool = b.model.__dict__["_adapt_graphs"]
    assert pool.rows == 1
    kept = b.sessions._items["a"]
    assert isinstance(kept[1], PackedRow) and kept[1].n == len(kept[0])  # every layer in one tensor
    assert kept[1].data.untyped_storage().data_ptr() != pool.kv.untyped_storage().data_ptr()
    b.generate([Request(p, g, (), 12, session=f"s{i}") for i, p in enumerate(prompts)])
    assert b.model.__dict__["_adapt_graphs"].rows == 4
    for key in ("s0", "s1", "s2"):
        packed = b.sessions._items[key][1]
        assert packed.data.untyped_storage().data_ptr() != b.model.__dict__["_adapt_graphs"].kv.untyped_storage().data_ptr()


def test_a_pass_that_would_outgrow_the_pool_runs_outside_the_graphs(domain, tiny, monkeypatch):
    """Graphed passes pad each row's new tokens to a power of two, so a decode can need more columns than
    its tokens: a pass the graphs do not take (here refused now and then) runs `forward` on the same
    cache, and the actions stay those of the model's forward."""
    from adaptbench.llm import batch_pass

    ours, plain = _sharp(tiny, device=DEVICE), _sharp(tiny, device=DEVICE)
    batch_pass.set_mode(ours.model, "graphs")
    ours.model.__dict__["_adapt_lean"] = False
    batch_pass.set_mode(plain.model, "hf")
    refused = []
    real = batch_pass.DecodeGraphs.takes

    def tight(self, layers, most):
        ok = real(self, layers, most) and layers[0].get_seq_length() % 7 != 3  # now and then: "no room"
        refused.append(not ok)
        return ok

    monkeypatch.setattr(batch_pass.DecodeGraphs, "takes", tight)
    assert _actions(domain, ours, 5) == _actions(domain, plain, 5)
    assert any(refused) and not all(refused)


def test_a_pool_layer_that_outgrows_the_pool_leaves_it_with_its_positions():
    """Writing past the pool's capacity moves the layer to a buffer of its own, keeping every position;
    the pool no longer holds it (so no graph replays over it)."""
    import torch
    from transformers import LlamaConfig, LlamaForCausalLM

    from adaptbench.llm.batch_pass import DecodeGraphs

    cfg = LlamaConfig(vocab_size=32, hidden_size=16, intermediate_size=32, num_hidden_layers=2,
                      num_attention_heads=4, num_key_value_heads=2)
    graphs = DecodeGraphs(LlamaForCausalLM(cfg).eval(), rows=2, capacity=8)
    keys = torch.randn(2, 2, 6, 4)
    layers = graphs.adopt([_Layer(keys, -keys) for _ in range(2)])
    assert graphs.holds(layers) and graphs.takes(layers, 2) and not graphs.takes(layers, 3)
    new = torch.randn(2, 2, 4, 4)
    k, v = layers[0].update(new, -new)
    assert k.shape[2] == 10 and torch.equal(k[:, :, :6], keys) and torch.equal(k[:, :, 6:], new)
    assert torch.equal(v, -k) and not graphs.holds(layers)


class _Layer:
    """A cache layer as `DecodeGraphs.adopt` reads one."""

    def __init__(self, keys, values):
        self.keys, self.values = keys, values

    def get_seq_length(self) -> int:
        return self.keys.shape[2]



@pytest.mark.parametrize("mode", ["hf", "graphs"])
def test_rollouts_in_two_lanes_act_as_one_batch_and_each_lane_has_its_own_pool(domain, tiny, mode, monkeypatch):
    """Half-batches decoded in turn (`lanes.run`, forced here with ADAPT_DECODE_LANES=2: two lanes of 3
    and 2 rows, stopped rows riding) take the same actions as one batch through the model's forward; in
    graphs mode each lane decodes in a pool of its own, and both lanes' passes ran."""
    from adaptbench.llm import batch_pass, decode, lanes

    monkeypatch.setattr(decode, "COMPACT_BYTES", 0)
    ours, plain = _sharp(tiny, device=DEVICE), _sharp(tiny, device=DEVICE)
    batch_pass.set_mode(ours.model, mode)
    ours.model.__dict__["_adapt_lean"] = False
    batch_pass.set_mode(plain.model, "hf")
    seen = []
    real = decode.steps

    def counted(model, rows, *args, lane=0, **kw):
        seen.append((lane, len(rows)))
        return real(model, rows, *args, lane=lane, **kw)

    monkeypatch.setattr("adaptbench.llm.hf.steps", counted)
    want = _actions(domain, plain, 5)
    monkeypatch.setenv(lanes.LANES_ENV, "2")
    assert _actions(domain, ours, 5) == want
    assert (0, 3) in seen and (1, 2) in seen
    pools = [ours.model.__dict__.get(name) for name in ("_adapt_graphs", "_adapt_graphs1")]
    if mode == "graphs":
        assert all(pools) and pools[0].kv.data_ptr() != pools[1].kv.data_ptr()
    else:
        assert not any(pools)


def test_lanes_split_rows_evenly_and_are_used_for_graphed_batches_on_a_gpu_only(tiny, monkeypatch):
    """`split` gives contiguous ranges differing by at most one row; `count` gives one lane on the CPU
    and for small batches, two for the graphed passes on CUDA from 2 x LANE_MIN rows; the environment
    overrides it, never beyond a lane a row."""
    from adaptbench.llm import batch_pass, lanes

    assert lanes.split(5, 2) == [range(0, 3), range(3, 5)]
    assert lanes.split(64, 2) == [range(0, 32), range(32, 64)]
    assert lanes.split(3, 1) == [range(0, 3)]
    b = _sharp(tiny)
    monkeypatch.delenv(lanes.LANES_ENV, raising=False)
    batch_pass.set_mode(b.model, "graphs")
    assert lanes.count(b.model, 64) == (2 if b.model.device.type == "cuda" else 1)
    assert lanes.count(b.model, 2 * lanes.LANE_MIN - 1) == 1
    monkeypatch.setenv(lanes.LANES_ENV, "2")
    assert lanes.count(b.model, 5) == 2 and lanes.count(b.model, 1) == 1


def test_run_steps_lanes_in_turn_and_returns_each_result():
    """Generators are stepped round-robin (each yields after queuing a pass) until all have returned."""
    from adaptbench.llm.lanes import run

    order = []

    def lane(name, n):
        for i in range(n):
            order.append((name, i))
            yield
        return name

    assert run([lane("a", 3), lane("b", 1)]) == ["a", "b"]
    assert order == [("a", 0), ("b", 0), ("a", 1), ("a", 2)]
