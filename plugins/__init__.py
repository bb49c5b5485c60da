"""Built-in symfuse stage implementations, one module per implementation.

Each module is registered through an entry point in the ``symfuse`` group of this
project's ``pyproject.toml``, exactly as a third-party plugin would be.
"""
