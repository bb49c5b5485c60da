"""Several grasps per object, the later ones chosen by ``paper``, ``random`` or
``information`` (docs/method.md §11): how the model improves grasp by grasp.

Every catalogue object, and every scanned mesh ``DIR/*/textured.obj`` when the sweep is
given ``--scans DIR`` (the YCB scans, for instance), stands at 10 object yaws uniform over a
full turn (seeded; ``--repeats`` changes the count, ``--quick`` keeps one yaw of two
objects). At each pose one trial per strategy grasps it three times (``trial.grasps = 3``)
with the hand the planners choose (``trial.gripper = "auto"``, their ranked candidates) and
VC initialisation; the three trials share the seed, so their scene, view and first grasp
are the same and they differ from the second grasp on. A trial stops early when no feasible
grasp remains; its later grasps then count with the estimate it ended with.

The report gives, per strategy and grasp, the median over trials of Stage 2's median
deviation from the true surface and of its plane errors (all trials, and the trials whose
first grasp leaves more than :data:`HARD_MM`); how much the second grasp reduced the
deviation on those (Stage 2's, and the selected stage's: the estimate a trial reports),
and how much more with ``information`` than with ``random`` pose by
pose, with a bootstrap interval (a few dozen poses leave the mean uncertain); and how often
a grasp made the estimate worse than the grasp before it, by the estimator's own
consistency check (Stage 2 consistent before, flagged after) and by the truth (Stage 2's
median deviation up by more than :data:`WORSE_MM`); and what the later grasps did to the
object and how they were fused: how many were not fused, how many only located the earlier
grasps' shape, how far they moved the object, how many moved it beyond the estimator's
re-grasp noise, and the hard poses' second-grasp gains within and beyond it; and how often
the later grasps failed to deliver, by the planner's score of their plans.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from pipeline.catalogue.objects import list_objects
from pipeline.config import NEXT_GRASP_STRATEGIES
from pipeline.estimation.later_grasps import EARLIER_SHAPE
from pipeline.experiments import ExperimentOptions, SweepTask
from pipeline.experiments.common import failures_section, fmt, task_seed
from pipeline.experiments.definitions import TRIAL_WORKER_IMPORTS
from pipeline.experiments.init import yaws_deg
from pipeline.experiments.paper_tasks import paper_task, sweep_params
from pipeline.experiments.paper_trial import run_paper_trial
from pipeline.experiments.rows import count_rows, failure_lines, finished_rows, value
from pipeline.experiments.sweep import write_csv

NAME = "explore"
#: Each task is a full trial: the workers load its modules once.
WORKER_IMPORTS = TRIAL_WORKER_IMPORTS

DESCRIPTION = (
    "three grasps per pose, later ones chosen by paper, random or information: deviation "
    "after each grasp (catalogue, and --scans DIR)"
)
#: The experiment reads the sweep's ``--scans`` folder.
READS_SCANS = True
STRATEGIES = NEXT_GRASP_STRATEGIES
GRASPS = 3
YAWS = 10
QUICK_YAWS = 1
QUICK_OBJECTS = ("cd_drive", "spray_bottle")
#: Trials whose first grasp leaves Stage 2 more than this far from the truth (median, mm).
HARD_MM = 2.0
#: A grasp made the estimate worse by the truth when Stage 2's median deviation grew by
#: more than this (mm): above the run-to-run jitter of the deviation itself.
WORSE_MM = 0.5
#: The deviation the second-grasp gains are measured on: Stage 2's, and the selected
#: stage's (the estimate a trial reports, docs/method.md §9).
STAGE2_DEVIATION = "stage2_deviation_median_mm"
SELECTED_DEVIATION = "selected_deviation_median_mm"
#: A later grasp moved the object beyond the re-grasp noise ``Q`` when it shifted or
#: turned it by more than this many of ``Q``'s stds.
REGRASP_SIGMAS = 2.0
#: Resamples of the bootstrap intervals; they are seeded, so a report is reproducible.
BOOTSTRAP_RESAMPLES = 10_000


def objects(options: ExperimentOptions) -> list[tuple[str, str]]:
    """``(label, trial.object)`` of every object the sweep grasps."""
    names = [info.name for info in list_objects()]
    if options.quick:
        names = [name for name in names if name in QUICK_OBJECTS]
    found = [(name, name) for name in names]
    if options.scans is not None:
        found += [
            (path.parent.name, str(path))
            for path in sorted(Path(options.scans).glob("*/textured.obj"))
        ]
    return found


def tasks(options: ExperimentOptions) -> list[SweepTask]:
    count = QUICK_YAWS if options.quick else (options.repeats or YAWS)
    result = []
    # Yaw by yaw over every object: a sweep stopped early has covered every object alike.
    for index, yaw in enumerate(yaws_deg(options.seed, count)):
        for label, name in objects(options):
            pose = f"{label}/yaw{index:02d}"
            for strategy in STRATEGIES:
                key = f"{pose}/{strategy}"
                params = {
                    "object": name,
                    "label": label,
                    "strategy": strategy,
                    "init": "vc",
                    "gripper": "auto",
                    "paper_grasp": False,
                    "yaw_deg": float(yaw),
                    "seed": task_seed(options.seed, pose),
                    "overrides": [
                        "trial.pictures=false",
                        f"trial.grasps={GRASPS}",
                        f"trial.next_grasp={strategy}",
                    ],
                    **sweep_params(options, key),
                }
                result.append(paper_task(key, params))
    return result


def run_one(params: dict) -> dict[str, Any]:
    return run_paper_trial(params)


def after_grasp(row: Mapping[str, Any], k: int, field: str) -> float:
    """``grasp{k}_{field}`` of a row; a trial that stopped before grasp ``k`` keeps the
    estimate of its last grasp."""
    made = int(row.get("grasps_made") or 0)
    return value(row, f"grasp{min(k, made)}_{field}") if made else float("nan")


def _median(rows: Sequence[Mapping[str, Any]], k: int, field: str) -> float:
    values = np.array([after_grasp(row, k, field) for row in rows])
    return float(np.nanmedian(values)) if np.isfinite(values).any() else float("nan")


def _flagged(row: Mapping[str, Any], k: int) -> bool:
    return row.get(f"grasp{k}_stage2_consistent") is not True


def worse_grasps(row: Mapping[str, Any]) -> tuple[list[bool], list[bool]]:
    """For each grasp after the first of a trial: whether it made the estimate worse by the
    consistency check (Stage 2 consistent after the grasp before, flagged after this one)
    and by the truth (Stage 2's median deviation up by more than :data:`WORSE_MM`)."""
    by_check, by_truth = [], []
    for k in range(2, int(row.get("grasps_made") or 0) + 1):
        by_check.append((not _flagged(row, k - 1)) and _flagged(row, k))
        before = value(row, f"grasp{k - 1}_{STAGE2_DEVIATION}")
        after = value(row, f"grasp{k}_{STAGE2_DEVIATION}")
        by_truth.append(bool(after - before > WORSE_MM))
    return by_check, by_truth


def worse_counts(rows: Sequence[Mapping[str, Any]]) -> tuple[int, int, int, int, int]:
    """Over ``rows``: ``(grasps after the first, of them worse by the check, worse by the
    truth, trials, trials with some grasp worse by the check)`` (:func:`worse_grasps`)."""
    grasps = by_check = by_truth = trials = trials_by_check = 0
    for row in rows:
        check, truth = worse_grasps(row)
        grasps += len(check)
        by_check += sum(check)
        by_truth += sum(truth)
        trials += 1
        trials_by_check += any(check)
    return grasps, by_check, by_truth, trials, trials_by_check


def hard_rows(rows: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    """Finished trials whose first grasp leaves Stage 2 more than :data:`HARD_MM` off."""
    return [
        row for row in finished_rows(rows) if value(row, f"grasp1_{STAGE2_DEVIATION}") > HARD_MM
    ]


def _by_strategy(rows: Sequence[Mapping[str, Any]]) -> dict[str, list[Mapping[str, Any]]]:
    return {s: [row for row in rows if row["params"]["strategy"] == s] for s in STRATEGIES}


def _second_grasp_reduction(row: Mapping[str, Any], field: str = STAGE2_DEVIATION) -> float:
    """How much the second grasp reduced the median deviation ``field`` (mm)."""
    return after_grasp(row, 1, field) - after_grasp(row, 2, field)


def second_grasp_gain(
    rows: Sequence[Mapping[str, Any]], field: str = STAGE2_DEVIATION
) -> tuple[float, float]:
    """Mean and median reduction of the median deviation ``field`` (mm; Stage 2's by
    default) from grasp 1 to 2."""
    gains = np.array([_second_grasp_reduction(row, field) for row in rows])
    gains = gains[np.isfinite(gains)]
    if not gains.size:
        return float("nan"), float("nan")
    return float(gains.mean()), float(np.median(gains))


def _pose(row: Mapping[str, Any]) -> tuple[str, float]:
    return row["params"]["label"], row["params"]["yaw_deg"]


def _paired_differences(rows: Sequence[Mapping[str, Any]], first: str, second: str) -> np.ndarray:
    """Per pose where both made their second grasp, how much more strategy ``first``'s
    second grasp reduced Stage 2's median deviation than ``second``'s (mm)."""
    gains: dict[str, dict[tuple[str, float], float]] = {first: {}, second: {}}
    for row in rows:
        strategy = row["params"]["strategy"]
        if strategy in gains:
            gains[strategy][_pose(row)] = _second_grasp_reduction(row)
    differences = np.array(
        [gain - gains[second][pose] for pose, gain in gains[first].items() if pose in gains[second]]
    )
    return differences[np.isfinite(differences)]


def paired_gain_ranks(
    rows: Sequence[Mapping[str, Any]], first: str, second: str
) -> tuple[int, int, float]:
    """The poses where strategy ``first``'s second grasp reduced Stage 2's median deviation
    more than ``second``'s and those where less (paired as in
    :func:`paired_gain_difference`), and the two-sided p of the Wilcoxon signed-rank test
    of the differences (poses that tie are left out; NaN when none differ). Ranks weigh
    each pose alike, where a few grasps that push the object far set the mean."""
    differences = _paired_differences(rows, first, second)
    differences = differences[differences != 0.0]
    better, worse = int(np.sum(differences > 0)), int(np.sum(differences < 0))
    if not differences.size:
        return better, worse, float("nan")
    from scipy.stats import wilcoxon

    return better, worse, float(wilcoxon(differences).pvalue)


def paired_gain_difference(
    rows: Sequence[Mapping[str, Any]], first: str, second: str
) -> tuple[float, float, float, int]:
    """How much more strategy ``first``'s second grasp reduced Stage 2's median deviation
    than ``second``'s, paired by pose (the two share the scene and the first grasp): the
    mean difference over the poses where both made their second grasp (mm), its 95 %
    bootstrap interval over those poses (percentile, seeded) and their number. NaN when no
    pose has both; the mean alone bounds the interval when one pose has, or all differ alike."""
    differences = _paired_differences(rows, first, second)
    if not differences.size:
        return float("nan"), float("nan"), float("nan"), 0
    mean = float(differences.mean())
    if differences.size == 1 or np.ptp(differences) == 0.0:
        return mean, mean, mean, int(differences.size)
    from scipy.stats import bootstrap

    interval = bootstrap(
        (differences,),
        np.mean,
        n_resamples=BOOTSTRAP_RESAMPLES,
        method="percentile",
        rng=np.random.default_rng(0),
    ).confidence_interval
    return mean, float(interval.low), float(interval.high), int(differences.size)


def located_only(row: Mapping[str, Any], k: int) -> bool:
    """Whether grasp ``k`` of ``row`` only located the earlier grasps' shape: its joint
    fusion contradicted the evidence and the earlier shape took its place (docs/method.md
    §11), so its taxels said where the object stands but did not reshape the model."""
    return str(row.get(f"grasp{k}_stage2_hypothesis") or "").startswith(EARLIER_SHAPE)


class LaterGrasp(NamedTuple):
    """A grasp after the first: its number, whether it was fused, how far it moved the
    object's centre (mm) and turned it (absolute, deg), and the planner's score of its plan
    (in [0, 1]; NaN when the planner gives none)."""

    k: int
    fused: bool
    shift_mm: float
    turn_deg: float
    planner_score: float


def later_grasps(row: Mapping[str, Any]) -> list[LaterGrasp]:
    """Every grasp after the first a trial made, including the one it stopped on unfused."""
    return [
        LaterGrasp(
            k,
            bool(row[f"grasp{k}_fused"]),
            value(row, f"grasp{k}_object_shift_mm"),
            abs(value(row, f"grasp{k}_object_turn_deg")),
            value(row, f"grasp{k}_planner_score"),
        )
        for k in range(2, GRASPS + 1)
        if f"grasp{k}_fused" in row
    ]


def regrasp_bounds(row: Mapping[str, Any]) -> tuple[float, float] | None:
    """How far the estimator's re-grasp noise ``Q`` lets the object move between grasps:
    :data:`REGRASP_SIGMAS` of its std in translation (mm) and yaw (deg); None for an
    estimator without one."""
    params = row["params"].get("estimator_params") or {}
    if "regrasp_b_xy_m" not in params or "regrasp_b_theta_rad" not in params:
        return None
    return (
        REGRASP_SIGMAS * 1e3 * float(params["regrasp_b_xy_m"]),
        REGRASP_SIGMAS * float(np.degrees(params["regrasp_b_theta_rad"])),
    )


def _sweep_bounds(rows: Sequence[Mapping[str, Any]]) -> tuple[float, float] | None:
    """:func:`regrasp_bounds` of the first of ``rows`` that has them (one estimator per
    sweep), or None."""
    return next((b for row in rows if (b := regrasp_bounds(row)) is not None), None)


def _beyond(row: Mapping[str, Any], grasp: LaterGrasp) -> bool:
    """Whether ``grasp`` of ``row`` moved the object beyond :func:`regrasp_bounds` (False
    without them)."""
    bounds = regrasp_bounds(row)
    return bounds is not None and (grasp.shift_mm > bounds[0] or grasp.turn_deg > bounds[1])


def motion_lines(
    finished: Sequence[Mapping[str, Any]], hard: Sequence[Mapping[str, Any]]
) -> list[str]:
    """The report's section on what the later grasps did to the object, per strategy."""
    bounds = _sweep_bounds(finished)
    if bounds is None:
        return []
    lines = [
        "",
        "## What the later grasps did to the object",
        "",
        "A grasp moves the object as its pads close. The estimator follows it between "
        f"grasps within the re-grasp noise Q; beyond {REGRASP_SIGMAS:g} std of Q "
        f"({bounds[0]:.0f} mm or {bounds[1]:.1f} deg) a later grasp's taxels meet a model "
        "that stands elsewhere. A grasp not executed, or that touched one side only or "
        "nothing, is not fused and ends the trial. A fused grasp whose joint fusion with "
        "the earlier ones contradicted the evidence only locates the earlier shape: its "
        "taxels say where the object stands, not what it looks like. The last columns: the "
        "hard poses' second grasps, within and beyond those bounds, and the mean reduction "
        "of Stage 2's median deviation.",
        "",
        "| strategy | later grasps | not fused | located only | moved beyond Q "
        "| shift: median / 90 % (mm) | turn: median / 90 % (deg) "
        "| hard, within Q: n, reduction (mm) | hard, beyond Q: n, reduction (mm) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for strategy, members in _by_strategy(finished).items():
        made = [(row, grasp) for row in members for grasp in later_grasps(row)]
        if not made:
            continue
        shifts = np.array([grasp.shift_mm for _, grasp in made])
        turns = np.array([grasp.turn_deg for _, grasp in made])
        beyond = sum(_beyond(row, grasp) for row, grasp in made)
        unfused = sum(not grasp.fused for _, grasp in made)
        located = sum(grasp.fused and located_only(row, grasp.k) for row, grasp in made)
        split: dict[bool, list[float]] = {False: [], True: []}
        for row in _by_strategy(hard)[strategy]:
            for grasp in later_grasps(row):
                if grasp.k == 2:
                    split[_beyond(row, grasp)].append(_second_grasp_reduction(row))
        cells = [
            f"{len(gains)}, {fmt(float(np.nanmean(gains)), 2) if gains else '-'}"
            for gains in (split[False], split[True])
        ]
        lines.append(
            f"| {strategy} | {len(made)} | {_share(unfused, len(made))} "
            f"| {_share(located, len(made))} | {_share(beyond, len(made))} "
            f"| {fmt(float(np.nanmedian(shifts)))} / {fmt(float(np.nanpercentile(shifts, 90)))} "
            f"| {fmt(float(np.nanmedian(turns)))} / {fmt(float(np.nanpercentile(turns, 90)))} "
            f"| {cells[0]} | {cells[1]} |"
        )
    return lines


def _missed(row: Mapping[str, Any], grasp: LaterGrasp) -> bool:
    """Whether ``grasp`` of ``row`` failed to deliver: it was not fused, or it moved the
    object beyond what the estimator follows (:func:`regrasp_bounds`)."""
    return not grasp.fused or _beyond(row, grasp)


def score_lines(finished: Sequence[Mapping[str, Any]]) -> list[str]:
    """The report's section on how often the later grasps failed to deliver, by the
    planner's score of their plans: in thirds of all strategies' scored later grasps, so
    that the bands follow the planners' scale rather than a threshold of the report's."""
    if _sweep_bounds(finished) is None:
        return []
    made = [
        (row["params"]["strategy"], grasp.planner_score, _missed(row, grasp))
        for row in finished
        for grasp in later_grasps(row)
        if np.isfinite(grasp.planner_score)
    ]
    if len(made) < 3:
        return []
    low, high = np.quantile([score for _, score, _ in made], [1 / 3, 2 / 3])
    names = (f"below {low:.3f}", f"{low:.3f} to {high:.3f}", f"{high:.3f} and above")
    lines = [
        "",
        "## Later grasps by the planner's score",
        "",
        "The planner scores each grasp in [0, 1] by how squarely its pads meet the sides and "
        "how far it is from tipping the object. Per band of that score (thirds of all "
        "strategies' later grasps), the later grasps made and the share that failed to "
        "deliver (not fused, or moved the object beyond Q): made: failed (share).",
        "",
        "| strategy | " + " | ".join(f"score {name}" for name in names) + " |",
        "|---|" + "---|" * len(names),
    ]
    for strategy in _by_strategy(finished):
        cells = []
        for band in range(len(names)):
            missed = [
                miss
                for made_by, score, miss in made
                if made_by == strategy and int(np.searchsorted([low, high], score, "right")) == band
            ]
            cells.append(f"{len(missed)}: {_share(sum(missed), len(missed))}" if missed else "-")
        lines.append(f"| {strategy} | " + " | ".join(cells) + " |")
    return lines


def _share(count: int, total: int) -> str:
    return f"{count} ({100.0 * count / total:.1f} %)" if total else str(count)


def report(rows: list[dict], out_dir: Path) -> list[Path]:
    """``results.csv``, ``explore.png`` (median deviation and plane errors after each
    grasp per strategy, all trials and the hard ones) and ``report.md``."""
    from pipeline.reports.figures import line_figure

    out_dir = Path(out_dir)
    csv_path = write_csv(rows, out_dir / "results.csv")
    finished = finished_rows(rows)
    hard_keys = {(row["params"]["label"], row["params"]["yaw_deg"]) for row in hard_rows(rows)}
    # A pose is hard by its first grasp, which every strategy shares: keep all three.
    hard = [
        row for row in finished if (row["params"]["label"], row["params"]["yaw_deg"]) in hard_keys
    ]
    lines, panels = _per_grasp_section(rows, finished, hard)
    figure = line_figure(panels, out_dir / "explore.png", title="Deviation after each grasp")
    lines += _second_grasp_section(hard)
    lines += _worse_section(finished)
    lines += motion_lines(finished, hard)
    lines += score_lines(finished)
    lines += _per_object_section(finished)
    lines += failures_section(failure_lines(rows))
    report_path = out_dir / "report.md"
    report_path.write_text("\n".join(lines) + "\n")
    return [csv_path, figure, report_path]


def _per_grasp_section(
    rows: list[dict], finished: list[dict], hard: list[dict]
) -> tuple[list[str], list[Any]]:
    """The report's head: per grasp and strategy, the medians over all trials and over the
    hard ones; and the figure's panels of the same deviations."""
    from pipeline.reports.figures import LinePanel

    grasps = range(1, GRASPS + 1)
    lines = [
        "# Several grasps: where to grasp next",
        "",
        f"Trials: {count_rows(rows).text()}. Three grasps per trial; per grasp, the median "
        "over trials of Stage 2's median deviation from the true surface (mm) and of its "
        "plane angle (deg) and offset (mm) errors. A trial that stopped early keeps its last "
        "estimate.",
        "",
        "| trials | strategy | n | "
        + " | ".join(f"grasp {k}: dev / angle / offset" for k in grasps)
        + " |",
        "|---|---|---|" + "---|" * GRASPS,
    ]
    panels = []
    for subset, group in (("all", finished), (f"first grasp > {HARD_MM:g} mm", hard)):
        curves = {}
        for strategy, members in _by_strategy(group).items():
            cells = [
                f"{fmt(_median(members, k, STAGE2_DEVIATION), 2)} / "
                f"{fmt(_median(members, k, 'stage2_plane_angle_error_deg'))} / "
                f"{fmt(_median(members, k, 'stage2_plane_offset_error_mm'))}"
                for k in grasps
            ]
            lines.append(f"| {subset} | {strategy} | {len(members)} | " + " | ".join(cells) + " |")
            curves[strategy] = [_median(members, k, STAGE2_DEVIATION) for k in grasps]
        panels.append(
            LinePanel(
                f"{subset} ({len(group) // len(STRATEGIES)} poses)",
                "grasps",
                "median deviation, Stage 2 (mm)",
                list(grasps),
                curves,
            )
        )
    return lines, panels


def _second_grasp_section(hard: list[dict]) -> list[str]:
    """What the second grasp gained on the hard poses, per strategy, and whether
    information's gain beats random's and the paper's (paired by pose)."""
    lines = [
        "",
        f"## The second grasp on poses whose first leaves more than {HARD_MM:g} mm",
        "",
        "The reduction of Stage 2's median deviation, and of the selected stage's: the "
        "estimate a trial reports, which is Stage 0 where the evidence contradicts every "
        "fused model.",
        "",
    ]
    gains = {s: second_grasp_gain(members) for s, members in _by_strategy(hard).items()}
    lines += [
        "| strategy | trials | mean reduction (mm) | median reduction (mm) "
        "| selected: mean / median (mm) |",
        "|---|---|---|---|---|",
    ]
    for strategy, (mean, median) in gains.items():
        members = _by_strategy(hard)[strategy]
        selected = second_grasp_gain(members, SELECTED_DEVIATION)
        lines.append(
            f"| {strategy} | {len(members)} | {fmt(mean, 2)} | {fmt(median, 2)} "
            f"| {fmt(selected[0], 2)} / {fmt(selected[1], 2)} |"
        )
    lines += _gain_ratio_lines(gains["information"][0], gains["random"][0])
    for other in ("random", "paper"):
        lines += _paired_lines(hard, other)
    return lines


def _gain_ratio_lines(informed: float, drawn: float) -> list[str]:
    """Information's mean second-grasp gain against random's (target >= 1.3x)."""
    if np.isfinite(informed) and np.isfinite(drawn) and drawn > 0:
        verdict = "yes" if informed >= 1.3 * drawn else "no"
        return [
            "",
            f"Information's mean reduction is {informed / drawn:.2f}x random's "
            f"(target >= 1.3x): {verdict}.",
        ]
    if np.isfinite(informed) and np.isfinite(drawn):
        return [
            "",
            f"Random's mean reduction is {drawn:.2f} mm, not a reduction, so the target "
            f"(information's at least 1.3x random's) is no ratio here; information's is "
            f"{informed:.2f} mm. The paired difference below says whether the two are told "
            "apart.",
        ]
    return []


def _paired_lines(hard: list[dict], other: str) -> list[str]:
    """Information's second-grasp gain against ``other``'s, paired by pose: the mean
    difference with its bootstrap interval, and the signed-rank test."""
    difference, low, high, poses = paired_gain_difference(hard, "information", other)
    if not poses:
        return []
    better, worse, p_value = paired_gain_ranks(hard, "information", other)
    return [
        "",
        f"Paired by pose, information's second grasp reduced the deviation by "
        f"{fmt(difference, 2)} mm more than {other}'s (95 % bootstrap interval "
        f"{fmt(low, 2)} to {fmt(high, 2)} mm over {poses} pose{'s' * (poses != 1)}): "
        "an interval that holds 0 does not tell the two strategies apart."
        f" By rank, information's gained more at {better} poses and less at {worse} "
        f"(Wilcoxon signed-rank p = {fmt(p_value, 3)}): a p under 0.05 says the "
        "typical pose differs, even where a few large gains or losses keep the "
        "mean's interval wide.",
    ]


def _worse_section(finished: list[dict]) -> list[str]:
    """Later grasps that made the estimate worse, by the consistency check and by the truth."""
    lines = [
        "",
        "## Grasps that made the estimate worse",
        "",
        f"By the consistency check: Stage 2 consistent after the grasp before and flagged after "
        f"this one. By the truth: Stage 2's median deviation up by more than {WORSE_MM:g} mm. "
        "Target: at most 5 % of the trials, per strategy.",
        "",
        "| strategy | grasps after the first | worse by the check | worse by the truth "
        "| trials | trials with a grasp worse by the check |",
        "|---|---|---|---|---|---|",
    ]
    for strategy, members in _by_strategy(finished).items():
        total, by_check, by_truth, trials, bad_trials = worse_counts(members)
        lines.append(
            f"| {strategy} | {total} | {_share(by_check, total)} | {_share(by_truth, total)} "
            f"| {trials} | {_share(bad_trials, trials)} |"
        )
    return lines


def _per_object_section(finished: list[dict]) -> list[str]:
    """Per object, each strategy's Stage 2 median deviation after the first and last grasp."""
    lines = [
        "",
        "## Per object (Stage 2 median deviation, mm: after grasp 1 -> after grasp 3)",
        "",
        "| object | poses | " + " | ".join(STRATEGIES) + " |",
        "|---|---|" + "---|" * len(STRATEGIES),
    ]
    by_object: dict[str, list[Mapping[str, Any]]] = {}
    for row in finished:
        by_object.setdefault(row["params"]["label"], []).append(row)
    for label, members in by_object.items():
        cells = []
        for group in _by_strategy(members).values():
            first = _median(group, 1, STAGE2_DEVIATION)
            last = _median(group, GRASPS, STAGE2_DEVIATION)
            cells.append(f"{fmt(first, 2)} -> {fmt(last, 2)}")
        lines.append(f"| {label} | {len(members) // len(STRATEGIES)} | " + " | ".join(cells) + " |")
    return lines
