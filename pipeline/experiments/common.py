"""Helpers every experiment uses: the plugin registry, task seeds and report formatting."""

from __future__ import annotations

import functools
import math
import zlib
from collections.abc import Sequence

import numpy as np


def task_seed(base_seed: int, key: str) -> int:
    """A trial's seed, stable across runs and machines: CRC32 of the key mixed with the base."""
    sequence = np.random.SeedSequence([int(base_seed), zlib.crc32(key.encode("utf-8"))])
    return int(sequence.generate_state(1)[0])


def fmt(value: float | None, digits: int = 1) -> str:
    """A number for a Markdown table; '-' for None/NaN, 'inf' for infinity."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if math.isinf(value):
        return "inf"
    return f"{value:.{digits}f}"


def failures_section(failed: Sequence[str]) -> list[str]:
    """Markdown lines listing runs that failed (a stage refused, the row says why) or raised
    (empty when none did)."""
    if not failed:
        return []
    lines = ["", f"## Runs that failed or raised ({len(failed)})", ""]
    lines += [f"- `{line}`" for line in failed[:20]]
    if len(failed) > 20:
        lines.append(f"- ... and {len(failed) - 20} more (see results.csv)")
    return lines


@functools.cache
def plugin_registry():
    """The plugin registry (loaded once per process)."""
    from pipeline.registry import load_registry

    return load_registry()
