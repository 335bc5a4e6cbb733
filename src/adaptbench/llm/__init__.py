"""Language-model agents and users: prompts (jinja2 templates rendered through the model's chat
template), a tiny local model for tests, grammar-constrained decoding with llguidance, backends
(`transformers`, OpenAI-compatible servers) and the LLM policies and persona user (docs/llm.md).

Nothing here is imported by the core: modules that need torch import it themselves, and the
`models` extra installs it (`pip install torch==2.13.0` first for the CPU wheel, then
`pip install -e ".[models]"`).
"""
