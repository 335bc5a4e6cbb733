"""The simulator: scenes, world state, actions parsed with the generated grammar, observations, the
event trace with provenance, the `Env`, and the preference verifiers."""
