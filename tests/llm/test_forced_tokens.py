"""`training.forced_tokens`: no loss on the tokens of a bank question that the bank grammar forces."""

from __future__ import annotations

from .conftest import SKIP_MODELS

pytestmark = SKIP_MODELS


def _record(domain, agent="oracle-ask", task="eggs", persona="juan", seed=0):
    from adaptbench.agents.scripted import play
    from adaptbench.agents.users import OfflineUser
    from adaptbench.runtime.env import Env

    env = Env(domain, task, persona, seed, user=OfflineUser(domain, domain.persona[persona], domain.task[task]))
    play(agent, env)
    steps = [{"action": e.text, "ok": e.ok, "observation": e.observation, "reply": e.reply} for e in env.world.trace]
    return {"agent": agent, "persona": persona, "task": task, "seed": seed, "steps": steps}


def test_only_the_tokens_where_questions_part_keep_their_loss(domain, backend):
    from adaptbench.grammars.index import domain_questions
    from adaptbench.training.forced_tokens import forced, question_trie

    tok, questions = backend.tokenizer, domain_questions(domain)
    trie = question_trie(tok, questions)
    for q in questions:
        ids = tok(f'Ask "{q}"', add_special_tokens=False)["input_ids"] + [tok.eos_token_id]
        kept = [t for t, f in zip(ids, forced(trie, ids), strict=True) if not f]
        assert kept[0] == ids[0]  # asking or acting is always a choice
        # the kept tokens name the question: no other bank question has the same kept tokens at those places
        same = [o for o in questions if o != q and _kept_match(tok, trie, o, ids, kept)]
        assert not same, (q, same)
    look = tok("Look for bowl", add_special_tokens=False)["input_ids"] + [tok.eos_token_id]
    assert not any(forced(trie, look))  # an action that is no bank question loses nothing
    free = tok('Ask "Do you like jam?"', add_special_tokens=False)["input_ids"] + [tok.eos_token_id]
    assert not any(forced(trie, free))  # nor does a question outside the bank


def _kept_match(tok, trie, other, ids, kept) -> bool:
    from adaptbench.training.forced_tokens import forced

    oids = tok(f'Ask "{other}"', add_special_tokens=False)["input_ids"] + [tok.eos_token_id]
    okept = [t for t, f in zip(oids, forced(trie, oids), strict=True) if not f]
    return okept == kept


def test_masking_an_episode_keeps_every_other_label(domain, backend):
    from adaptbench.grammars.index import domain_questions
    from adaptbench.training.forced_tokens import IGNORE, mask_examples
    from adaptbench.training.pretrain import examples

    rec = _record(domain)
    asks = [s["action"] for s in rec["steps"] if s["action"].startswith("Ask ")]
    assert asks, "oracle-ask asks juan something on eggs"
    tok = backend.tokenizer
    data, _ = examples(domain, [rec], tok)
    masked, removed = mask_examples(data, tok, domain_questions(domain))
    assert removed > 0
    for (ids, labels), (mids, mlabels) in zip(data, masked, strict=True):
        assert ids == mids
        assert all(m in (t, IGNORE) for t, m in zip(labels, mlabels, strict=True))
        # every action still has its first token and, for all but the bank's questions, every token
        assert sum(t == tok.eos_token_id for t in mlabels) <= sum(t == tok.eos_token_id for t in labels)
    text = tok.decode([t for t in masked[0][1] if t != IGNORE])
    for s in rec["steps"]:
        if not s["action"].startswith("Ask "):
            assert s["action"] in text
