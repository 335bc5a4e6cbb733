"""Prompts: golden files for every kind (pytest --update-golden regenerates them), standard roles,
the action list from the spec, and left-truncation to a token budget (no model needed)."""

from __future__ import annotations

from pathlib import Path

import pytest

from adaptbench.llm.chat import check_roles, fit, render
from adaptbench.llm.prompts import KINDS, PromptBuilder, action_lines, persona_messages, reflection_messages

from .conftest import play

GOLDEN = Path(__file__).parent / "golden"


def as_text(prompt_or_messages, prefix: str = "") -> str:
    msgs = getattr(prompt_or_messages, "messages", prompt_or_messages)
    body = "".join(f"=== {m['role']} ===\n{m['content']}\n" for m in msgs)
    return body + (f"=== generation prefix ===\n{prefix!r}\n" if prefix else "")


class WordTokenizer:
    """A stand-in tokenizer: one token per whitespace-separated word, a plain chat template."""

    def apply_chat_template(self, messages, tokenize=False, add_generation_prompt=True):
        check_roles(messages)
        return "".join(f"<{m['role']}> {m['content']} </s> " for m in messages) + "<assistant> "

    def __call__(self, text, add_special_tokens=False):
        return {"input_ids": text.split()}


@pytest.mark.parametrize("kind", KINDS)
def test_golden_agent_prompts(domain, golden, kind):
    ep, made_after = play(domain)
    view = ep.view()
    persona = domain.persona["juan"]
    kw = {"made_after": made_after}
    if kind == "teacher":
        kw.update(preferences=[p.text for p in persona.preferences],
                  unmet=[v.text for v in ep.env.evaluate().verdicts if v.verdict == "violated"])
    if kind == "always_ask":
        kw["force_ask"] = True
    p = PromptBuilder(domain, kind).prompt(view, **kw)
    check_roles(p.messages)
    golden(GOLDEN / f"{kind}.txt", as_text(p, p.prefix))


def test_golden_persona_and_reflection(domain, golden):
    from adaptbench.llm.user import state_text

    ep, made_after = play(domain)
    persona = domain.persona["juan"]
    msgs = persona_messages(persona.name, ep.env.task.text, [p.text for p in persona.preferences],
                            state_text(ep.env.world), (("How do you like your eggs?", "Scrambled."),),
                            "Would you like milk in the eggs?", ("Open fridge_0", "Move egg_0 to counter_0"))
    check_roles(msgs)
    golden(GOLDEN / "persona.txt", as_text(msgs))
    refl = reflection_messages(PromptBuilder(domain, "planner"), ep.view(), "Declare Done",
                               "Pour whole_milk from milk_0 to bowl_0", made_after,
                               "Since Juan prefers whole milk, my next step is Pour whole_milk from milk_0 to bowl_0.")
    check_roles(refl)
    golden(GOLDEN / "reflection.txt", as_text(refl))


def test_action_list_comes_from_the_spec(domain):
    lines = action_lines(domain)
    assert [a.example for a in lines] == [a.example for a in domain.actions]
    assert lines[0].template == "Turn on <X>"
    assert not any(a.template.startswith("Ask") for a in action_lines(domain, ask=False))
    system = PromptBuilder(domain, "never_ask").system("- kitchen (kitchen)")
    assert "Ask <QUESTION>" not in system and "Ask <QUESTION>" in PromptBuilder(domain, "planner").system("x")


def test_history_and_progress_lines(domain):
    ep, made_after = play(domain)
    msgs = PromptBuilder(domain, "planner").messages(ep.view(), made_after=made_after)
    assert [m["role"] for m in msgs] == ["system", "user"] + ["assistant", "user"] * len(ep.history)
    assert msgs[2]["content"] == "Action: Look for eggs"
    assert "The user replied:" in msgs[5]["content"]
    for turn, m in zip(ep.history, msgs[3::2], strict=True):
        assert m["content"].startswith(f"Observation: {turn.observation}\n" if turn.observation else "The user replied:")
    for m in msgs[1:]:
        if m["role"] == "user":
            assert "You have not made anything yet." in m["content"]
            assert m["content"].endswith("What is the next action required to achieve the task: "
                                         "Prepare eggs for breakfast?")
    assert "omitted" not in msgs[1]["content"]


def test_custom_roles_are_refused():
    with pytest.raises(ValueError, match="non-standard"):
        check_roles([{"role": "robot", "content": "x"}])
    with pytest.raises(ValueError, match="alternate"):
        check_roles([{"role": "system", "content": "x"}, {"role": "assistant", "content": "y"}])


def test_left_truncation_keeps_the_system_and_says_so(domain):
    ep, made_after = play(domain)
    b = PromptBuilder(domain, "planner")
    tok = WordTokenizer()

    def build(omit):
        return b.prompt(ep.view(), omit=omit, made_after=made_after)

    full = len(render(tok, build(0)).split())
    p = fit(tok, build, full - 5)
    assert p.omitted == 1 and len(render(tok, p).split()) <= full - 5
    assert p.messages[0] == build(0).messages[0]
    assert "(1 earlier step omitted to fit the context.)" in p.messages[1]["content"]
    assert p.messages[2]["content"] == "Action: " + ep.history[1].action  # the oldest went first
    assert p.messages[-1] == build(0).messages[-1]
    tiny_budget = fit(tok, build, 10)
    assert tiny_budget.omitted == len(ep.history) - 1 and tiny_budget.meta["over_budget"] > 0
    assert tiny_budget.messages[-2]["content"] == "Action: " + ep.history[-1].action  # the last step stays
    assert fit(tok, build, None).omitted == 0
