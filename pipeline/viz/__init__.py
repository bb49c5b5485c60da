"""Visualisation of finished runs in external viewers (the optional ``viz`` extra)."""
