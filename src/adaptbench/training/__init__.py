"""Training: reflection data and Reflection-DPO and its baselines (heavy parts import torch lazily)."""
