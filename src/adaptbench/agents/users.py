"""The offline persona user moved to `adaptbench.runtime.users` (it is part of the environment the
agents act in); this name is kept for existing imports."""

from ..runtime.users import (  # noqa: F401
    NO_LOCATION,
    NO_PREFERENCE,
    OfflineUser,
    first_person,
    location_question,
    question_targets,
    singular,
    words,
)
