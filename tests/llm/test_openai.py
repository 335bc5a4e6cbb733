"""The `openai` backend against a local OpenAI-compatible server over the tiny model (`fake_server.py`:
`transformers serve` needs the serving extra and takes neither token-id prompts nor vLLM's grammar
field). Skipped, saying why, without the `models` extra."""

from __future__ import annotations

import pytest

from adaptbench.grammars import GrammarCache
from adaptbench.llm.chat import render
from adaptbench.llm.prompts import PromptBuilder
from adaptbench.runtime.index import runtime_index

from .conftest import SKIP_MODELS, play

pytestmark = SKIP_MODELS


@pytest.fixture(params=[True, False], ids=["enforcing", "ignoring-grammars"])
def server(request, backend):
    from .fake_server import serve

    srv, url = serve(backend, enforce=request.param)
    yield url, request.param
    srv.shutdown()


def _request(domain, tokenizer, parser):
    from adaptbench.llm.backend import Request

    ep, _ = play(domain)
    text = render(tokenizer, PromptBuilder(domain, "planner").prompt(ep.view()))
    grammar = GrammarCache(runtime_index(domain).grammar).state("eggs", ep.env.observed()).text
    return Request(text, grammar, (), 24, lambda t: parser.parse(t) is not None)


def test_generate_validates_and_retries_once(domain, tiny, server):
    from adaptbench.llm.openai_backend import OpenAIBackend

    url, enforce = server
    parser = runtime_index(domain).parser
    ob = OpenAIBackend(url, "tiny", str(tiny))
    req = _request(domain, ob.tokenizer, parser)
    outs = ob.generate([req, req])
    assert len(outs) == 2
    if enforce:
        assert all(o.accepted and parser.parse(o.text) for o in outs) and ob.retries == 0
        assert outs[0].prompt_tokens == len(ob.encode(req.prompt))
    else:  # the random model unconstrained never writes an action: asked again once, then reported
        assert ob.retries == 2 and all(o.accepted is False and o.stats["tries"] == 2 for o in outs)


def test_sampled_requests_carry_a_seed_from_their_key_else_from_the_run(domain, tiny, backend):
    from dataclasses import replace

    from adaptbench.llm.backend import request_seed
    from adaptbench.llm.openai_backend import OpenAIBackend

    from .fake_server import serve

    srv, url = serve(backend)
    try:
        ob = OpenAIBackend(url, "tiny", str(tiny), temperature=1.0, seed=5)
        assert ob.config()["sample_seed"] == 5
        req = replace(_request(domain, ob.tokenizer, runtime_index(domain).parser), validate=None, grammar=None)
        keyed = replace(req, key="planner/juan/eggs/0/4/action")
        others = [replace(req, key=f"other/{i}") for i in range(3)]
        alone, in_batch = ob.generate([keyed])[0], ob.generate([others[0], keyed, *others[1:]])[1]
        assert alone.text == in_batch.text  # the episode's step: the same seed, so the same sample, in any batch
        assert srv.bodies[0]["seed"] == request_seed(5, keyed.key) and srv.bodies[0]["temperature"] == 1.0
        srv.bodies.clear()
        two = [o.text for o in ob.generate([req]) + ob.generate([req])]
        run_seeds = [b["seed"] for b in srv.bodies]
        assert two[0] != two[1] and run_seeds[0] != run_seeds[1]  # keyless: the run's next seeds
        srv.bodies.clear()
        OpenAIBackend(url, "tiny", str(tiny), temperature=1.0, seed=5).generate([req, req])
        assert sorted(b["seed"] for b in srv.bodies) == sorted(run_seeds)  # ... the same in a new run
        srv.bodies.clear()
        OpenAIBackend(url, "tiny", str(tiny)).generate([keyed])
        assert "seed" not in srv.bodies[0] and srv.bodies[0]["temperature"] == 0.0  # greedy: no seed sent
    finally:
        srv.shutdown()


def test_score_matches_the_transformers_backend(domain, tiny, backend, server):
    from adaptbench.llm.openai_backend import OpenAIBackend

    url, _ = server
    ob = OpenAIBackend(url, "tiny", str(tiny))
    prompt = _request(domain, ob.tokenizer, runtime_index(domain).parser).prompt
    conts = ["Look for eggs", 'Ask "Scrambled?"']
    for a, b in zip(ob.score(prompt, conts), backend.score(prompt, conts), strict=True):
        assert a.logprobs == pytest.approx(b.logprobs, abs=2e-4)


def test_score_ids_in_vllms_prompt_logprobs_form_match_the_transformers_backend(domain, tiny, backend):
    """The scoring primitive on both backends: groups of (prompt ids, [completion ids]) give the same
    log-probabilities, the served one read from vLLM's `prompt_logprobs` of token-id prompts."""
    from adaptbench.llm.backend import continuation_ids
    from adaptbench.llm.openai_backend import OpenAIBackend

    from .fake_server import serve

    srv, url = serve(backend, logprobs="vllm")
    try:
        ob = OpenAIBackend(url, "tiny", str(tiny))
        p = ob.encode(_request(domain, ob.tokenizer, None).prompt)
        a, b = (continuation_ids(ob.tokenizer, t) for t in ("Look for eggs", 'Ask "Scrambled?"'))
        groups = [(p, [a, b]), (p[:-2], [b]), (p, [])]
        served, local = ob.score_ids(groups), backend.score_ids(groups)
        assert [len(g) for g in served] == [len(g) for g in local] == [2, 1, 0]
        for x, y in zip([*served[0], *served[1]], [*local[0], *local[1]], strict=True):
            assert len(x) == len(y) > 0 and x == pytest.approx(y, abs=2e-4)
        assert all(isinstance(q["prompt"], list) and q["prompt_logprobs"] == 0 for q in srv.bodies)
    finally:
        srv.shutdown()


def test_unreachable_server_is_a_clear_error(tiny):
    from adaptbench.llm.backend import Request
    from adaptbench.llm.openai_backend import OpenAIBackend, ServerError

    ob = OpenAIBackend("http://127.0.0.1:9/v1", "tiny", str(tiny), timeout=2)
    with pytest.raises(ServerError, match="127.0.0.1:9"):
        ob.generate([Request("<|bos|>x", None, (), 2)])


def test_completions_carry_the_servers_token_ids_and_score_them(domain, tiny, backend, server):
    """vLLM's `return_token_ids`: the served completion's ids (EOS included) are the local backend's, and
    scoring them gives the local scores; with text the end token is scored as well."""
    from adaptbench.llm.openai_backend import OpenAIBackend

    url, enforce = server
    ob = OpenAIBackend(url, "tiny", str(tiny))
    req = _request(domain, ob.tokenizer, runtime_index(domain).parser)
    out = ob.generate([req])[0]
    if enforce:
        local = backend.generate([req])[0]
        assert out.token_ids == local.token_ids and out.token_ids[-1] == ob.tokenizer.eos_token_id
        assert out.stats["canonical"] == local.stats["canonical"]
    (served,) = ob.score(req.prompt, [out.token_ids])
    (mine,) = backend.score(req.prompt, [out.token_ids])
    assert served.token_ids == mine.token_ids == out.token_ids
    assert served.logprobs == pytest.approx(mine.logprobs, abs=2e-4)
