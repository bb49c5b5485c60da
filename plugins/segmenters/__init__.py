"""Segmenter plugins: the object's points cut out of a view."""
