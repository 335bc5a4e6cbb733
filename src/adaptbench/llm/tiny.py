"""A tiny local model for tests and the CPU default, built with no download.

    path = init_tiny(domain, "models/tiny")      # tokenizer trained on the domain's text + random Llama
    model = AutoModelForCausalLM.from_pretrained(path); tok = AutoTokenizer.from_pretrained(path)

The tokenizer is a byte-level BPE (any text encodes; entity ids, verbs and the prompts' words become
few tokens) trained locally with `tokenizers` on the domain's text: the rendered prompts of every
kind, entity ids and descriptions, substances, action examples, verbs, tasks and preferences. It
carries a chat template with the standard roles. The model is a small Llama, randomly initialised from
a seed; both are saved with `save_pretrained` and load back through the Auto classes like any model.
"""

from __future__ import annotations

from pathlib import Path

SPECIALS = ("<|pad|>", "<|bos|>", "<|end|>", "<|system|>", "<|user|>", "<|assistant|>")
# Pre-tokens: a word (or a run of punctuation) with the one space after it, or other whitespace. The space
# goes with the word before it, so the prompt's prefix "Action: " ends on a token boundary and an action
# is tokenized the same whether generated after it or read back in the history (a GPT-2 style split,
# "Action:" + " Look", would tokenize the history differently from what the model generates).
WORDS = r"\w+ ?|[^\w\s]+ ?|\s+"
# How text splits into pre-tokens (`--words`). "joined": WORDS, a word with the space after it (the default,
# what the shipped students use). "spaced": a space is a pre-token of its own and an id splits at its
# underscore ("desk_0" -> "desk", "_", "0"), so a word is the same token wherever it stands: in the user's
# answer, in an id, at an action's end. Joined gives "desk " ("my standing desk or") and "desk" ("desk_0"),
# "avocado " ("avocado as a side") and "avocado" ("Look for avocado"). The prompts are ~1.7x as many tokens.
WORD_SPLITS = {"joined": WORDS, "spaced": r"[^\W_]+|_|[^\w\s]+|\s+"}
CHAT_TEMPLATE = ("{{ bos_token }}{% for m in messages %}"
                 "{% if m['role'] not in ['system', 'user', 'assistant'] %}"
                 "{{ raise_exception('unknown role ' + m['role']) }}{% endif %}"
                 "<|{{ m['role'] }}|>\n{{ m['content'] }}<|end|>\n{% endfor %}"
                 "{% if add_generation_prompt %}<|assistant|>\n{% endif %}")


def corpus(domain) -> list:
    """The domain's text the tokenizer is trained on (prompts, ids, descriptions, actions, verbs,
    tasks, preferences and observations of a scene)."""
    from ..harness.policy import View
    from ..runtime.observe import describe, layout
    from ..runtime.scene import sample_scene
    from ..runtime.world import World
    from .prompts import KINDS, PromptBuilder, fill

    world = World(domain, sample_scene(domain, 0, True))
    lay = layout(world)
    texts = [lay]
    for kind in KINDS:
        b = PromptBuilder(domain, kind)
        texts.append(b.system(lay, [p.text for p in domain.personas[0].preferences]))
        texts.append(b.turn(domain.tasks[0].text, None))
    texts += [describe(world, e) for e in world.specs]
    texts += [f"{e.id} {e.description} {e.category}" for e in domain.entities]
    texts += [f"{s.id} {s.description} {s.category}" for s in domain.substances]
    texts += [f"{a.example}\n{a.summary}" for a in domain.actions]
    texts += [" ".join(vs) for _, vs in domain.verb_groups]
    texts += [t.text for t in domain.tasks]
    texts += [f"{p.text}\n{p.answer}" for per in domain.personas for p in per.preferences]
    texts.append(fill("persona", user="Juan", task=domain.tasks[0].text, preferences=("x",), state=lay))
    view = View("e", domain.tasks[0].id, domain.tasks[0].text, lay)
    texts.append(str(view))
    return texts


def train_tokenizer(domain, vocab_size: int = 4096, words: str = "joined"):
    """A byte-level BPE tokenizer trained on `corpus(domain)`, its pre-tokens split as `WORD_SPLITS[words]`,
    wrapped for transformers with the chat template and special tokens."""
    from tokenizers import Regex, Tokenizer, decoders, models, pre_tokenizers, trainers
    from transformers import PreTrainedTokenizerFast

    tok = Tokenizer(models.BPE())
    tok.pre_tokenizer = pre_tokenizers.Sequence([
        pre_tokenizers.Split(Regex(WORD_SPLITS[words]), behavior="isolated"),
        pre_tokenizers.ByteLevel(add_prefix_space=False, use_regex=False)])
    tok.decoder = decoders.ByteLevel()
    trainer = trainers.BpeTrainer(vocab_size=vocab_size, special_tokens=list(SPECIALS), show_progress=False,
                                  initial_alphabet=pre_tokenizers.ByteLevel.alphabet())
    tok.train_from_iterator(corpus(domain), trainer=trainer)
    return PreTrainedTokenizerFast(tokenizer_object=tok, bos_token="<|bos|>", eos_token="<|end|>",
                                   pad_token="<|pad|>", chat_template=CHAT_TEMPLATE, padding_side="left",
                                   model_max_length=16384)


def tiny_model(tokenizer, seed: int = 0, hidden: int = 64, layers: int = 2, heads: int = 4):
    """A randomly initialised small Llama for `tokenizer` (same seed, same weights)."""
    import torch
    from transformers import LlamaConfig, LlamaForCausalLM

    config = LlamaConfig(vocab_size=len(tokenizer), hidden_size=hidden, intermediate_size=hidden * 2,
                         num_hidden_layers=layers, num_attention_heads=heads, num_key_value_heads=heads // 2,
                         max_position_embeddings=16384, tie_word_embeddings=True,
                         bos_token_id=tokenizer.bos_token_id, eos_token_id=tokenizer.eos_token_id,
                         pad_token_id=tokenizer.pad_token_id)
    torch.manual_seed(seed)
    model = LlamaForCausalLM(config)
    model.generation_config.pad_token_id = tokenizer.pad_token_id
    model.generation_config.eos_token_id = tokenizer.eos_token_id
    return model


def init_tiny(domain, out, seed: int = 0, vocab_size: int = 4096, hidden: int = 64, layers: int = 2,
              words: str = "joined") -> Path:
    """Build the tiny tokenizer (pre-tokens: `WORD_SPLITS[words]`) and model and save both into `out`
    (created); returns the path."""
    if words not in WORD_SPLITS:
        raise ValueError(f"unknown word split '{words}' (choose from: {', '.join(WORD_SPLITS)})")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    tok = train_tokenizer(domain, vocab_size, words)
    model = tiny_model(tok, seed, hidden, layers)
    tok.save_pretrained(out)
    model.save_pretrained(out)
    return out
