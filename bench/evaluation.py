"""The evaluation alone: its processor time on one trial's recorded inputs, its profile, and
its scores against another revision's, bit for bit.

Run: ``python bench/evaluation.py [--trial default|sdh|table3] [--repeats N] [--profile]
[--baseline REV] [--rounds N]``.

One warm trial (after a warm-up trial; pictures off) runs with the evaluation's calls
recorded: every stage's estimate, the ground truth and the model. The evaluation then runs
alone on those inputs, as ``run_trial`` calls it (each stage's scores, the deviation floor,
the model meshes' scores), each time with a fresh ground truth (its samples, its mesh's
tree and its solid built again, as in a trial), on a single-threaded BLAS as in a trial:
the median processor time of ``--repeats`` runs. ``--profile`` prints the top functions by
own time over three runs (cProfile on the processor clock, which stretches the small calls).

``--baseline REV`` runs the revision's evaluation (unpacked as ``sweep_speed.py`` does) on
the same inputs in a process of its own, the two trees alternating for ``--rounds``
rounds, and compares every score of the last runs bit for bit.

``--trial table3`` records the first trial of ``symfuse sweep table3``.

Target (issue 41): the default trial's evaluation at most 0.3 s of processor time.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import os
import pickle
import pstats
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import fields
from pathlib import Path

import numpy as np
from planner_check import differences
from summary import record
from sweep_speed import ROOT, unpack

TARGET_S = 0.3
TRIALS = {"default": [], "sdh": ["trial.gripper=sdh"]}


def recorded_inputs(trial: str) -> dict:
    """The evaluation's inputs in the second of two warm trials of ``trial``."""
    import pipeline.run.trial as trial_module
    from pipeline.config import load_config
    from pipeline.registry import load_registry

    registry = load_registry()
    if trial in TRIALS:
        config = load_config(registry, overrides=["trial.pictures=false", *TRIALS[trial]])
    else:
        from pipeline.experiments import ExperimentOptions
        from pipeline.experiments.definitions import EXPERIMENTS
        from pipeline.experiments.paper_tasks import trial_config

        config = trial_config(EXPERIMENTS[trial].tasks(ExperimentOptions())[0].params)
    inputs: dict = {"stages": [], "floor": None, "model": None}
    calls = {name: getattr(trial_module, name) for name in ("evaluate_stage", "model_scores")}
    calls["deviation_floor"] = trial_module.deviation_floor

    def evaluate_stage(stage, truth, centre):
        inputs["stages"].append((stage, centre))
        inputs["truth"] = {f.name: getattr(truth, f.name) for f in fields(truth)}
        return calls["evaluate_stage"](stage, truth, centre)

    def deviation_floor(stage, truth):
        inputs["floor"] = stage
        return calls["deviation_floor"](stage, truth)

    def model_scores(model, truth):
        inputs["model"] = model
        return calls["model_scores"](model, truth)

    replaced = {
        "evaluate_stage": evaluate_stage,
        "deviation_floor": deviation_floor,
        "model_scores": model_scores,
    }
    try:
        for name, call in replaced.items():
            setattr(trial_module, name, call)
        with tempfile.TemporaryDirectory() as folder:
            trial_module.run_trial(config, registry, Path(folder) / "warm-up")
            inputs["stages"].clear()
            trial_module.run_trial(config, registry, Path(folder) / "trial")
    finally:
        for name, call in calls.items():
            setattr(trial_module, name, call)
    return inputs


def evaluate(inputs: dict) -> tuple:
    """The evaluation of ``run_trial`` on recorded inputs: each stage's metrics and
    distances, the deviation floor, the model meshes' scores."""
    from pipeline.metrics.evaluation import (
        GroundTruth,
        deviation_floor,
        evaluate_stage,
        model_scores,
    )

    truth = GroundTruth(**inputs["truth"])
    stages = [evaluate_stage(stage, truth, centre) for stage, centre in inputs["stages"]]
    floor = None if inputs["floor"] is None else deviation_floor(inputs["floor"], truth)
    model = None if inputs["model"] is None else model_scores(inputs["model"], truth)
    return stages, floor, model


def measure(inputs: dict, repeats: int, profile: bool) -> tuple[list[float], tuple, str]:
    """Processor seconds of ``repeats`` evaluations (after one unmeasured), the last one's
    results and, if asked, the profile's top functions."""
    from pipeline.run.runner import one_blas_thread

    seconds, text = [], ""
    with one_blas_thread():
        evaluate(inputs)
        for _ in range(repeats):
            started = time.process_time()
            results = evaluate(inputs)
            seconds.append(time.process_time() - started)
        if profile:
            profiler = cProfile.Profile(time.process_time)
            for _ in range(3):
                profiler.runcall(evaluate, inputs)
            out = io.StringIO()
            pstats.Stats(profiler, stream=out).sort_stats("tottime").print_stats(15)
            text = out.getvalue()
    return seconds, results, text


def plain(value: object) -> object:
    """An evaluation's results as JSON-like values (arrays as lists, dataclasses as dicts),
    for :func:`planner_check.differences`."""
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if hasattr(value, "__dataclass_fields__"):
        return plain(vars(value))
    return value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trial", default="default", choices=[*TRIALS, "table3"])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--profile", action="store_true")
    parser.add_argument("--baseline", help="git revision to compare this tree with")
    parser.add_argument("--rounds", type=int, default=2, help="processes per tree (--baseline)")
    parser.add_argument("--measure", nargs=2, type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.measure:  # a tree's evaluation on recorded inputs, in a process of its own
        inputs = pickle.loads(args.measure[0].read_bytes())
        seconds, results, text = measure(inputs, args.repeats, args.profile)
        args.measure[1].write_bytes(pickle.dumps(results))
        print(json.dumps({"seconds": seconds, "profile": text}))
        return
    inputs = recorded_inputs(args.trial)
    if not args.baseline:
        seconds, _, text = measure(inputs, args.repeats, args.profile)
        median = statistics.median(seconds)
        print(f"{args.trial} trial's evaluation, median of {args.repeats}: {median:.3f} s cpu")
        print(text, end="")
        record(f"{args.trial} trial's evaluation alone (s cpu)", median, "s", TARGET_S)
        return
    with tempfile.TemporaryDirectory(prefix="symfuse-evaluation-") as name:
        folder = Path(name)
        trees = {"baseline": unpack(args.baseline, folder), "this tree": ROOT}
        (folder / "inputs.pickle").write_bytes(pickle.dumps(inputs))
        runs: dict[str, list[float]] = {label: [] for label in trees}
        texts = {}
        for _ in range(args.rounds):
            for label, tree in trees.items():
                command = [sys.executable, str(ROOT / "bench/evaluation.py"), "--measure"]
                command += [str(folder / "inputs.pickle"), str(folder / f"{label}.pickle")]
                command += ["--repeats", str(args.repeats)]
                command += ["--profile"] if args.profile else []
                env = {
                    **os.environ,
                    "PYTHONPATH": os.pathsep.join([str(tree), str(ROOT / "bench")]),
                }
                done = subprocess.run(command, env=env, cwd=tree, check=True, capture_output=True)
                measured = json.loads(done.stdout)
                runs[label].append(statistics.median(measured["seconds"]))
                texts[label] = measured["profile"]
        results = [pickle.loads((folder / f"{label}.pickle").read_bytes()) for label in trees]
    print(f"{args.trial} trial's evaluation against {args.baseline[:10]}: processor time (s),")
    print(f"each round the median of {args.repeats}")
    for label, seconds in runs.items():
        rounds = ", ".join(f"{s:.3f}" for s in seconds)
        print(f"{label:<10} {statistics.median(seconds):.3f} ({rounds})")
        print(texts[label], end="")
    found = differences(*(plain(r) for r in results))
    print(f"scores that differ, bit for bit: {len(found)}")
    for where, by in found[:20]:
        print(f"    {where}: by {by:.3g}")


if __name__ == "__main__":
    main()
