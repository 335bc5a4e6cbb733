"""TRL's environment class: tools TRL can describe and call, the reward from the verifiers, tool calls the
tiny model's prepared tokenizer parses, and a GRPO smoke run that changes the adapter and logs rewards."""

from __future__ import annotations

import importlib.util
import json

import pytest

MISSING = [m for m in ("torch", "transformers", "trl", "peft", "datasets") if importlib.util.find_spec(m) is None]
pytestmark = pytest.mark.skipif(bool(MISSING), reason=f"train extra not installed (missing {', '.join(MISSING)}): "
                                "pip install torch==2.13.0 && pip install -e '.[train,envs]'")


def test_tools_and_reward(domain, oracle_eggs):
    from transformers.utils import get_json_schema

    from adaptbench.envs.trl_env import OVER, environment_class

    env = environment_class(domain)()
    names = {get_json_schema(m)["function"]["name"]: get_json_schema(m) for m in (env.act, env.ask, env.done)}
    assert set(names) == {"act", "ask", "done"}
    assert names["act"]["function"]["parameters"]["required"] == ["action"]
    opening = env.reset(task="eggs", persona="juan", seed=0, prompt="ignored")
    assert "Prepare eggs" in opening and env.get_reward() == 0.0
    assert env.ask("How do you like your eggs?").startswith("User: ")
    assert "I don't understand" in env.act("Juggle the eggs")
    for a in oracle_eggs["actions"][:-1]:
        env.act(a)
    assert env.done().endswith(OVER) and env.act("Look for eggs") == OVER
    assert env.get_reward() == pytest.approx(oracle_eggs["verdicts"]["satisfaction_rate"]) and env.get_reward() > 0


def test_tiny_tokenizer_parses_tool_calls(tiny, domain):
    from transformers import AutoModelForCausalLM, AutoTokenizer
    from trl.chat_template_utils import add_response_schema, parse_response, supports_tool_calling

    from adaptbench.envs.grpo import prepare_tokenizer
    from adaptbench.envs.trl_env import environment_class

    tok, model = AutoTokenizer.from_pretrained(tiny), AutoModelForCausalLM.from_pretrained(tiny)
    assert not supports_tool_calling(tok)
    tok = add_response_schema(prepare_tokenizer(tok, model))
    assert supports_tool_calling(tok) and model.get_input_embeddings().weight.shape[0] == len(tok)
    text = '<tool_call>\n{"name": "act", "arguments": {"action": "Look for eggs"}}\n</tool_call><|im_end|>'
    prefix = tok.apply_chat_template([{"role": "user", "content": "hi"}], add_generation_prompt=True)["input_ids"]
    msg = parse_response(tok, tok(text, add_special_tokens=False)["input_ids"], prefix=list(prefix))
    call = msg["tool_calls"][0]["function"]
    env = environment_class(domain)()
    env.reset(task="eggs", persona="juan", seed=0)
    assert getattr(env, call["name"])(**call["arguments"]).startswith("Found egg_0")


def test_grpo_smoke_changes_adapter_and_logs_rewards(tiny, tmp_path, capsys):
    """`adapt train grpo` on a user's spec (the small test spec, not the paper's): 2 steps on the CPU."""
    from safetensors.torch import load_file

    from adaptbench.cli.main import main
    from tests.conftest import SMALL

    out = tmp_path / "grpo"
    rc = main(["train", "grpo", "--model", str(tiny), "--spec", str(SMALL), "--out", str(out), "--steps", "2",
               "--generations", "4", "--max-completion", "16", "--max-tool-calls", "2", "--holdout", "1",
               "--eval-episodes", "1", "--lr", "1e-2"])
    assert rc == 0
    assert "held-out reward (verifiers' satisfaction rate): before" in capsys.readouterr().out
    weights = load_file(out / "adapter" / "adapter_model.safetensors")
    lora_b = [w for n, w in weights.items() if "lora_B" in n]
    assert lora_b and any(w.abs().sum() > 0 for w in lora_b)  # LoRA's B starts at zero: training moved it
    rows = [json.loads(line) for line in (out / "log.jsonl").read_text().splitlines()]
    logged = [r for r in rows if "rewards/AdaptEnvironment/mean" in r]
    assert len(logged) == 2 and all(0.0 <= r["rewards/AdaptEnvironment/mean"] <= 1.0 for r in logged)
    assert all("rewards/tool_format_reward/mean" in r for r in logged)
    held = [r for r in rows if r.get("event") == "held_out"]
    assert [r["when"] for r in held] == ["before", "after"]
    before = (out / "log.jsonl").read_bytes(), (out / "adapter" / "adapter_model.safetensors").read_bytes()
    args = ["train", "grpo", "--model", str(tiny), "--spec", str(SMALL), "--out", str(out), "--steps", "2",
            "--generations", "4", "--max-completion", "16", "--max-tool-calls", "2", "--holdout", "1",
            "--eval-episodes", "1", "--lr", "1e-2"]
    assert main(args) == 0  # a rerun of the finished run trains nothing and changes nothing
    assert "already holds this finished run" in capsys.readouterr().err
    assert ((out / "log.jsonl").read_bytes(), (out / "adapter" / "adapter_model.safetensors").read_bytes()) == before
