"""``result.json``: the one document of an estimate, as ``trial``, ``fuse`` and ``complete``
write it.

Every command starts the document the same way (:func:`start_document`: the version and the
command, then what the command ran on), records the initial state and the estimate with the
same entries (:func:`init_to_json`, :func:`estimate_entries`), writes the estimate's files
the same way (:func:`write_estimate_files`) and, when a stage fails after data was written,
records how far it got (:func:`record_failure`). The commands differ only in what they add
between those parts (a trial its scene and grasps, ``fuse`` its inputs); the key order of
each command's document is part of its format (docs/formats.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pipeline import __version__
from pipeline.asset.files import write_model
from pipeline.config import ModelSettings
from pipeline.io.formats import (
    bias_to_json,
    estimate_to_json,
    plane_to_json,
    selection_to_json,
    symmetry_to_json,
    write_completed_clouds,
    write_json,
)
from pipeline.types import EstimateResult, SymmetryInit

#: The file every estimating command writes its document to, in its output folder.
RESULT_FILE = "result.json"


def start_document(command: str, **fields: Any) -> dict[str, Any]:
    """A new document: the package version, the command, then ``fields`` in order."""
    return {"symfuse": __version__, "command": command, **fields}


#: What ``init.completion`` says when the initialiser chose a leaning mirror plane.
LEANING_PLANE = (
    "leaning plane: the built-in estimators fuse the chosen plane (init.symmetry) in a "
    "seven-parameter state, each stage's 'symmetry' its estimate; 'plane' is the best "
    "vertical plane, for estimators that take vertical planes only"
)


def init_to_json(
    init: SymmetryInit,
    source: str | None = None,
    status: bool = False,
    hypotheses: int = 0,
) -> dict[str, Any]:
    """The ``init`` entry: where the initial plane came from (``source``: an initialiser's
    name or an option, when the command names it), the plane and bias, the initialiser's
    status (``status``) and its best ``hypotheses`` ranked hypotheses (0: none)."""
    entry: dict[str, Any] = {} if source is None else {"source": source}
    entry |= {
        "plane": plane_to_json(init.plane),
        "symmetry": symmetry_to_json(init.proposed),
        "kind_scores": init.kind_scores,
        "bias": bias_to_json(init.bias),
    }
    if init.kind == "plane":
        entry["completion"] = LEANING_PLANE
    if status:
        entry["status"] = init.status
    if hypotheses:
        entry["hypotheses"] = [
            {**plane_to_json(h.plane), "score": h.score, "violations": h.violations}
            for h in init.hypotheses[:hypotheses]
        ]
    return entry


def estimate_entries(
    result: EstimateResult,
    metrics: Sequence[dict[str, Any]] | None = None,
    trace: bool = True,
) -> dict[str, Any]:
    """``stages`` (each stage of ``result``, with its ``metrics`` when evaluated and its
    iteration trace unless ``trace`` is false), ``selected_stage`` and
    ``selection_reason``."""
    stages = estimate_to_json(result)
    if not trace:
        stages = [{key: value for key, value in s.items() if key != "trace"} for s in stages]
    if metrics is not None:
        stages = [{**s, "metrics": m} for s, m in zip(stages, metrics, strict=True)]
    return {"stages": stages, **selection_to_json(result)}


def write_estimate_files(
    out_dir: Path,
    result: EstimateResult,
    model: ModelSettings,
    table_height_m: float | None,
    viewpoint_m: np.ndarray,
) -> tuple[Any, dict[str, Any]]:
    """``completed_stage{0,1,2}.ply`` and the model's files (:func:`pipeline.asset.files.
    write_model`) into ``out_dir``; the model's mesh (None when none was built) and the
    document's ``model`` entry."""
    write_completed_clouds(out_dir, result)
    return write_model(out_dir, result, model, table_height_m, viewpoint_m)


def write_document(out_dir: Path, document: dict[str, Any]) -> Path:
    """Write ``document`` as ``out_dir``'s ``result.json``."""
    return write_json(Path(out_dir) / RESULT_FILE, document)


def record_failure(out_dir: Path, document: dict[str, Any], reason: str, **extra: Any) -> Path:
    """Mark ``document`` failed with ``reason`` (and ``extra`` entries after it) and write
    it: a failure after data was written is a result that says how far the run got."""
    document.update(status="failed", reason=reason, **extra)
    return write_document(out_dir, document)
