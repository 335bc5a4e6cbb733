"""The `verifiers` taskset id `adapt_breakfast`: ADAPT episodes (adaptbench.envs.verifiers_env).

verifiers imports a taskset id as a top-level module and takes the Taskset and Env subclasses it exports.
"""

from adaptbench.envs import verifiers_env

if verifiers_env.vf is None:
    raise ImportError("adapt_breakfast needs the verifiers library: pip install 'verifiers>=0.4' "
                      "(or pip install -e '.[verifiers]')")

AdaptTaskset, AdaptVfEnv, load_environment = (verifiers_env.AdaptTaskset, verifiers_env.AdaptVfEnv,
                                              verifiers_env.load_environment)

__all__ = ["AdaptTaskset", "AdaptVfEnv", "load_environment"]
