"""The `verifiers` taskset id `adapt_breakfast`: ADAPT episodes (adaptbench.envs.verifiers_env).

verifiers imports a taskset id as a top-level module and takes the Taskset and Env subclasses it exports.
"""

from adaptbench.envs.verifiers_env import AdaptTaskset, AdaptVfEnv, load_environment

__all__ = ["AdaptTaskset", "AdaptVfEnv", "load_environment"]
