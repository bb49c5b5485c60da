"""Robot descriptions (URDF + meshes) shipped with symfuse; :data:`ROOT` is their folder,
valid in a checkout and in an installed wheel alike."""

from pathlib import Path

ROOT = Path(__file__).resolve().parent
