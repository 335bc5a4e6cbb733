"""Random-weight models of real models' shapes, for speed measurements without a download.

    path = smollm2_shape(domain, "/tmp/smol")   # SmolLM2-135M's LlamaConfig, random weights, local tokenizer

The weights are random (speed only, never quality) and the tokenizer is the project's locally trained
byte-level BPE (`llm.tiny.train_tokenizer`): the model's vocabulary (its embedding and output layer) has
SmolLM2's 49,152 rows, the tokenizer fewer (a corpus this small has fewer merges), so tokens past the
tokenizer are never allowed by the grammar. Prompts tokenize to about as many tokens as SmolLM2's
tokenizer gives (the project's text is what this tokenizer was trained on).
"""

from __future__ import annotations

from pathlib import Path

SMOLLM2_135M = dict(hidden_size=576, intermediate_size=1536, num_hidden_layers=30, num_attention_heads=9,
                    num_key_value_heads=3, vocab_size=49152, max_position_embeddings=8192, rms_norm_eps=1e-5,
                    rope_theta=100000.0, tie_word_embeddings=True)


def smollm2_shape(domain, out, seed: int = 0) -> Path:
    """Save a random-weight model of SmolLM2-135M's shape with the local tokenizer into `out` (kept
    when it is already there); returns the path."""
    import torch
    from transformers import LlamaConfig, LlamaForCausalLM

    from adaptbench.llm.tiny import train_tokenizer

    out = Path(out)
    if (out / "config.json").is_file() and (out / "model.safetensors").is_file():
        return out
    tok = train_tokenizer(domain, 49152)
    config = LlamaConfig(**SMOLLM2_135M, bos_token_id=tok.bos_token_id, eos_token_id=tok.eos_token_id,
                         pad_token_id=tok.pad_token_id)
    torch.manual_seed(seed)
    model = LlamaForCausalLM(config)
    model.generation_config.pad_token_id = tok.pad_token_id
    model.generation_config.eos_token_id = tok.eos_token_id
    out.mkdir(parents=True, exist_ok=True)
    tok.save_pretrained(out)
    model.save_pretrained(out)
    return out
