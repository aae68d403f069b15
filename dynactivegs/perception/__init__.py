"""Perception: per-pixel uncertainty beta from image features (DESIGN.md §5, Perception)."""
