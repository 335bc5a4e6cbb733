"""Action grammars generated from the compiled domain: the index (`build_index`), the Lark emitter
with its levels and variants, per-state grammars updated incrementally, a parser over them and a
random sampler.

    index = build_index(domain)              # once per CompiledDomain, passed explicitly
    cache = GrammarCache(index)
    g = cache.state("eggs", env.observed())  # level "observed", variant "default"
    text = g.update(env.observed())          # after the next step: only changed terminals re-emitted
"""

from .emit import LEVELS, QUESTION_SETS, VARIANTS, Base, Observed, build_base
from .index import GrammarIndex, build_index
from .state import GrammarCache, StateGrammar

__all__ = ["LEVELS", "QUESTION_SETS", "VARIANTS", "Base", "GrammarCache", "GrammarIndex", "Observed", "StateGrammar",
           "build_base", "build_index"]
