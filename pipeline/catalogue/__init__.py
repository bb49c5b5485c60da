"""The object catalogue: the shipped objects as meshes, and user meshes from files."""
