"""Rollouts, evaluation tables, reflection and training (heavy parts import torch lazily)."""
