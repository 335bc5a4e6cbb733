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


def test_a_completion_keeps_all_but_the_forced_question_tokens(domain, backend):
    """In a trainer's completion (`Action: `, the action, the end of turn) only a bank question's forced tokens
    are skipped: the prefix, `Ask`, the tokens where questions part and the template's own tokens keep their loss."""
    from adaptbench.grammars.index import domain_questions
    from adaptbench.training.forced_tokens import completion_keep, forced, question_trie

    tok, questions = backend.tokenizer, domain_questions(domain)
    trie, eos = question_trie(tok, questions), tok.eos_token_id
    prefix = tok("Action: ", add_special_tokens=False)["input_ids"]
    for q in questions[:5]:
        action = tok(f'Ask "{q}"', add_special_tokens=False)["input_ids"] + [eos]
        keep = completion_keep(prefix + action + [7], trie, eos)
        assert keep[:len(prefix)] == (1,) * len(prefix) and keep[-1] == 1
        assert list(keep[len(prefix):-1]) == [0 if f else 1 for f in forced(trie, action)]
        assert 0 in keep
    look = prefix + tok("Look for bowl", add_special_tokens=False)["input_ids"] + [eos]
    assert completion_keep(look, trie, eos) == (1,) * len(look)


def test_dpo_and_sft_rows_carry_the_mask(domain, backend):
    """`mask_forced_rows` marks both completions; the SFT row's labels skip the masked tokens and the DPO
    collator's completion mask is 0 exactly there, for the chosen and the rejected sequence."""
    from adaptbench.grammars.index import domain_questions
    from adaptbench.training.trainers.encode import IGNORE, Encoded
    from adaptbench.training.trainers.engine import keep_mask_collator
    from adaptbench.training.trainers.rows import mask_forced_rows

    tok = backend.tokenizer
    eos = tok.eos_token_id
    ask = tuple(tok(f'Ask "{domain_questions(domain)[0]}"', add_special_tokens=False)["input_ids"] + [eos])
    look = tuple(tok("Look for bowl", add_special_tokens=False)["input_ids"] + [eos])
    rows = [Encoded(("juan", "eggs", 100, 1, 0), (5, 6, 7), ask, look), Encoded(("juan", "eggs", 100, 1, 1), (5, 6), look, ask)]
    masked, skipped = mask_forced_rows(rows, tok, domain_questions(domain))
    assert skipped == 2 * masked[0].chosen_keep.count(0) > 0
    assert masked[0].rejected_keep == (1,) * len(look) and masked[1].rejected_keep == masked[0].chosen_keep
    labels = masked[0].supervised()["labels"]
    assert labels[:3] == [IGNORE] * 3
    assert [x == IGNORE for x in labels[3:]] == [k == 0 for k in masked[0].chosen_keep]
    batch = keep_mask_collator(tok.pad_token_id)([r.preference() for r in masked])
    cm = batch["completion_mask"].tolist()
    assert cm[0][3:3 + len(ask)] == list(masked[0].chosen_keep) and cm[2][3:3 + len(look)] == [1] * len(look)
    assert cm[1][2:2 + len(look)] == [1] * len(look) and cm[3][2:2 + len(ask)] == list(masked[1].rejected_keep)
    assert all(x == 0 for row, p in zip(cm, (3, 2, 3, 2), strict=True) for x in row[:p])
