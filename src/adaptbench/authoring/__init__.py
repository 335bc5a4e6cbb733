"""Authoring helpers: skeletons of new personas and tasks, the vocabulary rules may use, and JSON Schemas
that carry the spec's declared names for editor completion."""

from .schemas import schemas
from .skeletons import add_to_splits, skeleton_path, skeleton_text
from .vocab import vocabulary

__all__ = ["add_to_splits", "schemas", "skeleton_path", "skeleton_text", "vocabulary"]
