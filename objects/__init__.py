"""The object catalogue shipped with symfuse; :data:`ROOT` is its folder, valid in a
checkout and in an installed wheel alike."""

from pathlib import Path

ROOT = Path(__file__).resolve().parent
