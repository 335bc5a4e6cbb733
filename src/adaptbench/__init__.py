"""adaptbench: the ADAPT benchmark as data — spec compiler, text simulator, verifiers and Reflection-DPO."""

__version__ = "0.1.0"
