"""Agents and users: the offline persona user, scripted agents, LLM planners."""
