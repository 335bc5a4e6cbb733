"""Authoring helpers: skeletons of new personas and tasks, the vocabulary rules may use, and JSON Schemas
that carry the spec's declared names for editor completion."""

from .schemas import schemas
from .skeletons import skeleton_path, skeleton_text
from .vocab import vocabulary

__all__ = ["schemas", "skeleton_path", "skeleton_text", "vocabulary"]
