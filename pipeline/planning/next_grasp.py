"""Where to grasp next: the next grasp of a multi-grasp trial, planned on the current estimate
(``trial.next_grasp``; docs/method.md §11).

After each grasp the estimator has a completed model (its selected stage: points, plane,
bias) and the covariance of the plane and bias. The planner of each hand the trial may use
(:class:`NextHand`: the first grasp's hand, or every hand of the world when it changes
hands) is asked for every feasible grasp on that model
(:meth:`pipeline.stages.GraspPlanner.alternatives`), and one strategy picks among them:

* ``paper``: the first grasp's rule again, the best-scored of the planners' own plans on
  the current model;
* ``random``: a feasible alternative drawn uniformly (seeded by the trial);
* ``information``: the alternative with the largest expected reduction of the completed
  model's positional uncertainty where the grasp will hold the object, its shape and its
  place (:func:`pipeline.estimation.uncertainty.expected_gain_m2` with
  :func:`~pipeline.estimation.uncertainty.model_gram`), from the taxels it is predicted
  to touch on the current model (:func:`predicted_contacts`) where no earlier grasp
  touched (:func:`new_places`) and the estimator's own measurement model, weighted by how
  likely the grasp is to deliver them (:func:`delivery`: the planner's score without its
  alignment factor, in [0, 1]: how squarely its pads meet the sides and how far it is
  from tipping the object), among the grasps weighted at least half the best
  (:data:`PLANNER_FLOOR`) and not predicted to turn the object further than the
  estimator follows (:func:`predicted_turn_rad`, :data:`TURN_SIGMAS`), and never a grasp
  already made (:func:`repeats`) while another of those teaches anything; the best
  delivered of them when none teaches anything. The planners
  score on one scale, as when the first grasp's hand is chosen
  (:mod:`pipeline.planning.hand_choice`).

The stop rule (:func:`stop_reason`) ends the trial once the plane offset and the hidden
side's shape are known well enough, or when the grasps run out.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import scipy.spatial

from pipeline.metrics import plane_after_bias
from pipeline.planning.candidate import alignment
from pipeline.planning.pad_contact import (
    PadContact,
    PadTaxels,
    curved_pad_taxels,
    flat_pad_taxels,
    pad_coverage,
)
from pipeline.types import (
    Bias,
    ClosingPad,
    Contacts,
    GraspPlan,
    GripperSpec,
    PointCloud,
    StageEstimate,
    SymmetryInit,
)

#: A predicted taxel touches the model when the surface in front of it lies within this of
#: the pad at its first touch (m): the planners' default touch tolerance.
TOUCH_TOLERANCE_M = 0.003

#: A predicted taxel this close to a place an earlier grasp touched (m) reads the same
#: surface: its own taxel cell (3.4 mm pitch) or the next, which is where the same plan lands
#: again after the millimetres the object moves between grasps.
SAME_PLACE_M = 0.005

#: A plan repeats an earlier one of the same hand when its closing direction is within this
#: angle of the earlier one's (half the planners' 15 deg step between directions; either
#: way for a parallel gripper, whose jaws swap) and its hand within :data:`SAME_PLACE_M`
#: of the earlier one's across that direction (half their 10 mm step between pad heights,
#: and more than the object moves between grasps): the planner's same grid cell on the
#: object, found again. Along the closing direction the hand's place does not count: the
#: pads close along it until they meet the sides, the same places wherever they start.
SAME_DIRECTION_RAD = math.radians(7.5)

#: ``information`` chooses among the alternatives whose :func:`delivery` is at least this
#: fraction of the best (a grasp already made included, though not chosen). Below it are
#: grasps that meet an edge or hold the object off its centre, which turn it as the pads
#: close: on the CD drive, third grasps there turned it 7-10 deg, more than the re-grasp
#: noise ``Q`` lets the estimator follow.
PLANNER_FLOOR = 0.5


#: ``information`` leaves out the grasps predicted to turn the object by more than this many
#: stds of the re-grasp noise's yaw (:func:`predicted_turn_rad`): the estimator follows the
#: object from one grasp to the next within ``Q``, and a turn beyond two stds of it is one
#: it does not expect.
TURN_SIGMAS = 2.0


@dataclass(frozen=True)
class MeasurementModel:
    """The estimator's model the information score predicts with (what the estimator's
    :meth:`~pipeline.stages.Estimator.measurement_model` gives; the built-in ``iekf``'s
    from its parameters): ``C_t`` and ``R`` as (along, across) the taxel normal (m), each
    point's prior std (m), whether the correspondences filter by facing, and the re-grasp
    noise ``Q`` (``(6, 6)`` over ``g``) the object's motion adds before every grasp after
    the first."""

    window_std_m: tuple[float, float]
    noise_std_m: tuple[float, float]
    point_std_m: float
    facing_filter: bool
    regrasp_noise: np.ndarray


@dataclass(frozen=True)
class Uncertainty:
    """How well the current estimate knows the object (m), from the plane-and-bias
    covariance (:mod:`pipeline.estimation.uncertainty`): the plane's offset std at the
    object, the hidden side's RMS positional std (where the object stands included), and
    the hidden side's RMS std against the visible side (the shape alone). The stop rule
    reads the first and the last, which more grasps reduce; the object's place each
    re-grasp unsettles again."""

    plane_offset_std_m: float
    hidden_side_std_m: float
    hidden_shape_std_m: float

    def to_json(self) -> dict[str, float]:
        return {
            "plane_offset_std_mm": 1e3 * self.plane_offset_std_m,
            "hidden_side_std_mm": 1e3 * self.hidden_side_std_m,
            "hidden_shape_std_mm": 1e3 * self.hidden_shape_std_m,
        }

    def stop_stds(self) -> str:
        """The stop rule's two stds, as text."""
        return (
            f"plane offset std {1e3 * self.plane_offset_std_m:.2f} mm and hidden shape std "
            f"{1e3 * self.hidden_shape_std_m:.2f} mm"
        )


def state_vector(stage: StageEstimate) -> np.ndarray:
    """``g = (b_theta, b_x, b_y, b_z, m_r, m_theta)`` of a stage (about its bias pivot),
    with the elevation ``m_phi`` last when the stage estimated a leaning plane."""
    bias, plane = stage.bias, stage.plane
    if stage.symmetry is None:
        return np.array([bias.yaw_rad, *bias.translation_m, plane.offset_m, plane.theta_rad])
    # The symmetry keeps the state's own normal (its sign too): the covariance's frame.
    n = stage.symmetry.direction
    angles = (np.arctan2(n[1], n[0]), np.arcsin(np.clip(n[2], -1.0, 1.0)))
    return np.array([bias.yaw_rad, *bias.translation_m, stage.symmetry.offset_m, *angles])


def uncertainty(stage: StageEstimate) -> Uncertainty:
    """The stds of ``stage`` (infinite when it has no covariance)."""
    from pipeline.estimation.uncertainty import (
        hidden_shape_std_m,
        hidden_side_gram,
        hidden_side_std_m,
        plane_offset_std_m,
    )

    covariance = np.asarray(stage.covariance, dtype=float)
    if not np.all(np.isfinite(covariance)):
        return Uncertainty(math.inf, math.inf, math.inf)
    g, pivot = state_vector(stage), stage.bias.pivot_m
    gram = hidden_side_gram(stage.points, g, pivot)
    return Uncertainty(
        plane_offset_std_m(covariance, g, pivot),
        hidden_side_std_m(covariance, gram),
        hidden_shape_std_m(covariance, gram),
    )


def stop_reason(
    known: Uncertainty,
    grasps_done: int,
    grasps_allowed: int,
    until_std_m: float | None,
    unfused: int = 0,
) -> str:
    """Why the trial stops after ``grasps_done`` grasps (``unfused`` of them not fused), or
    ``""`` to grasp again.

    It stops when the plane's offset std and the hidden shape std of ``known`` are both at
    most ``until_std_m`` (when given), else when ``grasps_allowed`` grasps were made (and
    then says how many were not fused and which std stayed above ``until_std_m``).
    """
    reached = until_std_m is not None and (
        known.plane_offset_std_m <= until_std_m and known.hidden_shape_std_m <= until_std_m
    )
    if reached:
        return (
            f"uncertainty reached: {known.stop_stds()} <= {1e3 * until_std_m:g} mm after "
            f"{grasps_done} grasp(s)"
        )
    if grasps_done < grasps_allowed:
        return ""
    made = f"grasps done: {grasps_done} of {grasps_allowed}"
    if unfused:
        made += f" ({unfused} not fused)"
    if until_std_m is None:
        return made
    stds = (
        ("plane offset std", known.plane_offset_std_m),
        ("hidden shape std", known.hidden_shape_std_m),
    )
    above = " and ".join(f"{name} {1e3 * std:.2f} mm" for name, std in stds if std > until_std_m)
    met = ", ".join(f"{name} {1e3 * std:.2f} mm" for name, std in stds if std <= until_std_m)
    return (
        f"{made}, before the uncertainty reached {1e3 * until_std_m:g} mm: {above} stayed "
        f"above it" + (f" ({met})" if met else "")
    )


def model_for_planning(
    stage: StageEstimate, viewpoint_m: np.ndarray | None
) -> tuple[PointCloud, SymmetryInit]:
    """The current model as a planner takes it: the visible points where the object was at
    the last grasp (moved by the bias), the camera's ``viewpoint_m`` (m, frame R) and the
    symmetry plane moved with them; the planner's completion mirrors the one through the
    other, which is the stage's model."""
    if viewpoint_m is not None:
        viewpoint_m = stage.bias.apply(np.asarray(viewpoint_m)[None, :])[0]
    cloud = PointCloud(stage.completed[: len(stage.points)], viewpoint_m=viewpoint_m)
    plane = plane_after_bias(stage.plane, stage.bias)
    return cloud, SymmetryInit(plane=plane, bias=Bias(pivot_m=cloud.points.mean(axis=0)))


@dataclass(frozen=True)
class PadApproach:
    """A pad closing horizontally along ``direction`` through ``origin_m`` (frame R)."""

    name: str
    origin_m: np.ndarray
    direction: np.ndarray
    taxels: PadTaxels


def pad_approaches(plan: GraspPlan, gripper: GripperSpec) -> list[PadApproach]:
    """How each tactile pad of ``plan`` closes on the object, as the hand declares
    (:attr:`~pipeline.types.GripperSpec.closing`): along its facing, turned by the plan's
    spread, from its finger's base (a parallel gripper's jaws: along the hand's x axis
    and back). The pads' centre height is that of the plan's predicted contacts (the
    hand's pad height is the planner's)."""
    T = np.asarray(plan.T_robot_hand, dtype=float)
    if len(plan.predicted_contacts) == 0 or not gripper.closing:
        return []
    height_m = float(np.mean(np.asarray(plan.predicted_contacts)[:, 2]))
    x_hand = np.array([T[0, 0], T[1, 0], 0.0]) / np.hypot(T[0, 0], T[1, 0])
    pads = {pad.name: pad for pad in gripper.pads}
    rotation = np.column_stack([x_hand[:2], [x_hand[1], -x_hand[0]]])
    bases = T[:2, 3] + np.array([closing.base_m for closing in gripper.closing]) @ rotation.T
    facings = np.array([_facing(c, plan.spread_rad) for c in gripper.closing]) @ rotation.T
    approaches = []
    for closing, base, facing in zip(gripper.closing, bases, facings, strict=True):
        pad = pads[closing.pad]
        taxels = (
            curved_pad_taxels(pad, height_m, closing.curved_rows, closing.curve_radius_m)
            if closing.curved_rows
            else flat_pad_taxels(pad, height_m)
        )
        approaches.append(
            PadApproach(
                pad.name,
                np.array([base[0], base[1], height_m]),
                np.array([facing[0], facing[1], 0.0]),
                taxels,
            )
        )
    return approaches


def _facing(closing: ClosingPad, spread_rad: float) -> tuple[float, float]:
    """``closing``'s facing in the palm's xy plane at the spread ``spread_rad``."""
    if closing.spread_sign == 0:
        return closing.facing
    angle = closing.spread_sign * spread_rad
    c, s = math.cos(angle), math.sin(angle)
    x, y = closing.facing
    return (c * x - s * y, s * x + c * y)


def _taxel_cells(points_m: np.ndarray, approach: PadApproach) -> np.ndarray:
    """The row-major taxel cell (a pitch across the motion and in height) each point lies
    in front of, -1 outside the pad's footprint."""
    taxels = approach.taxels
    lateral = np.array([-approach.direction[1], approach.direction[0], 0.0])
    u = (points_m - approach.origin_m) @ lateral
    cols = len(taxels.col_u)
    col = np.round((u - taxels.col_u[0]) / taxels.pitch_m).astype(int)
    gaps = np.abs(points_m[:, 2, None] - taxels.row_z[None, :])
    row = np.argmin(gaps, axis=1)
    inside = (col >= 0) & (col < cols) & (gaps[np.arange(len(row)), row] <= taxels.pitch_m / 2)
    return np.where(inside, row * cols + col, -1)


#: A pad of a plan that is predicted to touch the model, and how.
PadTouch = tuple[PadApproach, PadContact]


def pad_contacts(plan: GraspPlan, gripper: GripperSpec, model_m: np.ndarray) -> list[PadTouch]:
    """Each pad of ``plan`` that is predicted to touch the completed model ``model_m``
    (``(K, 3)``, frame R): it closes on the layer of the model facing it until its first
    taxel meets it (:func:`pipeline.planning.pad_contact.pad_coverage`)."""
    found = []
    for approach in pad_approaches(plan, gripper):
        contact = pad_coverage(
            model_m, approach.origin_m, approach.direction, approach.taxels, TOUCH_TOLERANCE_M
        )
        if contact is not None:
            found.append((approach, contact))
    return found


def predicted_turn_rad(touches: Sequence[PadTouch]) -> float:
    """How far a grasp whose pads touch as ``touches`` (:func:`pad_contacts`) is predicted
    to turn the object about the vertical (rad, about +z): the turn its pads share
    (:attr:`~pipeline.planning.pad_contact.PadContact.turn_rad`, the angle by which the
    side in front of each is turned from facing it), the smallest when all are turned the
    same way, else 0.

    An object turned by an angle turns every side by it, and pads pressing sides turned
    alike press them into line with themselves: a flat object held by parallel jaws at an
    angle to its faces turns by that angle. A round object held off its centre meets the
    pads turned opposite ways, and is pushed across rather than turned. 0 when no pad
    touches."""
    turns = np.array([contact.turn_rad for _, contact in touches])
    if not turns.size or not (np.all(turns > 0.0) or np.all(turns < 0.0)):
        return 0.0
    return float(turns[np.argmin(np.abs(turns))])


def predicted_contacts(plan: GraspPlan, gripper: GripperSpec, model_m: np.ndarray) -> Contacts:
    """The taxels ``plan`` is predicted to touch on the completed model ``model_m``
    (``(K, 3)``, frame R; :func:`pad_contacts`, :func:`taxel_readings`)."""
    return taxel_readings(pad_contacts(plan, gripper, model_m))


def taxel_readings(touches: Sequence[PadTouch]) -> Contacts:
    """The taxels of the pads ``touches`` (:func:`pad_contacts`): every taxel whose cell
    holds a touched model point reads a contact at the centroid of those points, its
    normal the pad's closing direction."""
    positions, normals, pads, indices = [], [], [], []
    for approach, contact in touches:
        cell = _taxel_cells(contact.points, approach)
        for index in np.unique(cell[cell >= 0]):
            positions.append(contact.points[cell == index].mean(axis=0))
            normals.append(approach.direction)
            pads.append(approach.name)
            indices.append(int(index))
    if not positions:
        return Contacts(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, str), np.zeros(0, int))
    return Contacts(np.array(positions), np.array(normals), pads, indices)


def new_places(contacts: Contacts, touched_m: np.ndarray) -> Contacts:
    """The taxels of ``contacts`` farther than :data:`SAME_PLACE_M` from every place in
    ``touched_m`` (``(K, 3)``, frame R), the surface earlier grasps touched.

    A taxel pressing where one pressed before reads the model's error at that place again:
    the camera noise of the points there, the detail the mirror image misses, the pad's
    compliance. That error repeats with the place; it does not average out as independent
    noise would, so only the taxels on new surface count as new information.
    """
    if len(contacts) == 0 or len(touched_m) == 0:
        return contacts
    distance, _ = scipy.spatial.cKDTree(touched_m).query(contacts.positions)
    return contacts.select(distance > SAME_PLACE_M)


def information_scores(
    stage: StageEstimate,
    plans: tuple[GraspPlan, ...],
    grippers: Mapping[str, GripperSpec],
    model: MeasurementModel,
    earlier: tuple[GraspPlan, ...] = (),
    touches: Sequence[Sequence[PadTouch]] | None = None,
) -> list[float]:
    """Each plan's expected reduction of the completed model's mean squared positional std
    where the grasp holds the object (m^2: the visible side moved by the grasp's bias, the
    hidden side by the bias and the plane) if its predicted taxels on new surface were
    fused into ``stage`` (module docstring), from the covariance the estimator will fuse
    them with: ``stage``'s plus the re-grasp noise. Each plan's taxels are those of its own
    hand, ``grippers[plan.gripper]``. The surface the ``earlier`` plans (the grasps fused so
    far) reach on the current model is not new (:func:`new_places`). ``touches``: each
    plan's :func:`pad_contacts` on ``stage``'s model, where already found. All zero when
    ``stage`` has no finite covariance (the best delivered is then taken)."""
    from pipeline.estimation.correspondences import PointIndex
    from pipeline.estimation.problem import grasp_contacts
    from pipeline.estimation.uncertainty import expected_gain_m2, model_gram, predicted_measurement

    covariance = np.asarray(stage.covariance, dtype=float).copy()
    size = len(model.regrasp_noise)  # on the bias: a leaning plane's elevation gets none
    covariance[:size, :size] += model.regrasp_noise
    if not np.all(np.isfinite(covariance)):
        return [0.0] * len(plans)  # an estimator without a covariance: nothing to rank by
    g, pivot, points = state_vector(stage), stage.bias.pivot_m, stage.points
    gram = model_gram(points, g, pivot)
    index = PointIndex(points)
    variance = np.full(len(points), model.point_std_m**2)
    touched = [
        predicted_contacts(plan, grippers[plan.gripper], stage.completed).positions
        for plan in earlier
    ]
    touched_m = np.concatenate(touched) if touched else np.zeros((0, 3))
    scores = []
    if touches is None:
        touches = [pad_contacts(plan, grippers[plan.gripper], stage.completed) for plan in plans]
    for touch in touches:
        contacts = new_places(taxel_readings(touch), touched_m)
        if len(contacts) == 0:
            scores.append(0.0)
            continue
        taxels = grasp_contacts(
            contacts, model.window_std_m, model.noise_std_m, model.facing_filter
        )
        jacobian, nuisance = predicted_measurement(
            index, points, g, pivot, taxels, covariance, variance
        )
        scores.append(expected_gain_m2(covariance, jacobian, nuisance, gram))
    return scores


def repeats(
    plan: GraspPlan, earlier: Sequence[GraspPlan], grippers: Mapping[str, GripperSpec]
) -> bool:
    """Whether ``plan`` is a grasp already made, one of ``earlier`` again
    (:data:`SAME_DIRECTION_RAD`, :data:`SAME_PLACE_M` across the earlier closing
    direction): its taxels would press where that grasp's pressed, whose error they repeat
    rather than average out (:func:`new_places`).
    """
    direction = np.asarray(plan.closing_direction, dtype=float)
    position = np.asarray(plan.T_robot_hand, dtype=float)[:3, 3]
    for before in earlier:
        if before.gripper != plan.gripper:
            continue
        closing = np.asarray(before.closing_direction, dtype=float)
        cosine = float(direction @ closing)
        if grippers[plan.gripper].fingers == 2:
            cosine = abs(cosine)
        offset = position - np.asarray(before.T_robot_hand, dtype=float)[:3, 3]
        moved = np.linalg.norm(offset - (offset @ closing) * closing)
        if cosine >= math.cos(SAME_DIRECTION_RAD) and moved <= SAME_PLACE_M:
            return True
    return False


@dataclass(frozen=True)
class NextGraspChoice:
    """The next grasp and why.

    Attributes:
        plan: the plan to execute (refused when the planner found none).
        strategy: the strategy that chose it.
        alternatives: the feasible plans it chose among (every hand's).
        scores: the information score of each alternative (m^2), ``information`` only;
            the choice maximises it times the alternative's :func:`delivery` among the
            alternatives whose delivery is at least :data:`PLANNER_FLOOR` of the best,
            leaving out those predicted to turn the object too far.
        turns_rad: each alternative's :func:`predicted_turn_rad`, ``information`` only.
        turn_limit_rad: the turn beyond which an alternative is left out
            (:data:`TURN_SIGMAS` stds of the re-grasp noise's yaw).
        chosen: index of ``plan`` among ``alternatives`` (None when refused).
        repeated: whether each alternative :func:`repeats` a grasp already made,
            ``information`` only.
    """

    plan: GraspPlan
    strategy: str
    alternatives: tuple[GraspPlan, ...] = ()
    scores: tuple[float, ...] = ()
    chosen: int | None = None
    turns_rad: tuple[float, ...] = ()
    turn_limit_rad: float = math.inf
    repeated: tuple[bool, ...] = ()

    def to_json(self) -> dict[str, Any]:
        return {
            "strategy": self.strategy,
            "alternatives": len(self.alternatives),
            "chosen": self.chosen,
            "scores_mm2": [1e6 * s for s in self.scores],
            "planner_scores": [_planner_score(plan) for plan in self.alternatives],
            "delivery": [delivery(plan) for plan in self.alternatives],
            "turns_deg": [math.degrees(turn) for turn in self.turns_rad],
            "turn_limit_deg": (
                None if math.isinf(self.turn_limit_rad) else math.degrees(self.turn_limit_rad)
            ),
            "grippers": [plan.gripper for plan in self.alternatives],
            "repeats": list(self.repeated),
        }


def _planner_score(plan: GraspPlan) -> float:
    """The planner's score of ``plan`` in [0, 1]; 1 when the planner gives none."""
    return 1.0 if math.isnan(plan.score) else float(plan.score)


def delivery(plan: GraspPlan) -> float:
    """How likely ``plan`` is to deliver the taxels it is predicted to touch, in [0, 1]: the
    planner's score without its alignment factor (:func:`~pipeline.planning.candidate.alignment`),
    which leaves how squarely the pads meet the sides and how far the grasp is from tipping
    the object. The alignment factor is the planners' stand-in for what the estimator learns
    from a grasp, which ``information`` computes itself; counted again, it halved the
    weight of the grasps that close along the plane, the only ones that feel where along
    the plane the object sits. A plan that does not record the one candidate it was made
    from (``GraspPlan.candidates``) keeps the planner's score."""
    score = _planner_score(plan)
    if len(plan.candidates) != 1:
        return score
    return min(1.0, score / alignment(math.radians(plan.candidates[0].closing_angle_deg)))


@dataclass(frozen=True)
class NextHand:
    """A hand a later grasp may be made with, and the planner that plans for it."""

    planner: Any  # a pipeline.stages.GraspPlanner
    gripper: GripperSpec


def choose_next_grasp(
    strategy: str,
    hands: Sequence[NextHand],
    stage: StageEstimate,
    model: MeasurementModel,
    rng: np.random.Generator,
    viewpoint_m: np.ndarray | None = None,
    earlier: tuple[GraspPlan, ...] = (),
    unfused: tuple[GraspPlan, ...] = (),
) -> NextGraspChoice:
    """Plan the next grasp on ``stage``'s model with each of ``hands`` and pick it by
    ``strategy``; ``viewpoint_m`` is the camera's position when the object was seen (m,
    frame R), ``earlier`` the plans of the grasps fused so far (each names its hand, which
    is one of ``hands``), ``unfused`` those of the later grasps that were not fused: no
    strategy chooses one of these again (:func:`repeats`)."""
    cloud, proposal = model_for_planning(stage, viewpoint_m)
    grippers = {hand.gripper.name: hand.gripper for hand in hands}
    if strategy == "paper":
        plans = [hand.planner.plan(cloud, proposal, hand.gripper) for hand in hands]
        feasible = [plan for plan in plans if plan.status == "ok"]
        best = max(feasible, key=_planner_score, default=plans[0])
        if best.status != "ok" or not repeats(best, unfused, grippers):
            return NextGraspChoice(best, strategy)
    alternatives = tuple(
        plan
        for hand in hands
        for plan in hand.planner.alternatives(cloud, proposal, hand.gripper)
        if not repeats(plan, unfused, grippers)
    )
    if not alternatives:
        first = hands[0]
        plan = first.planner.plan(cloud, proposal, first.gripper)
        if plan.status == "ok" and repeats(plan, unfused, grippers):
            plan = replace(plan, status="refused", reason="every feasible grasp was not fused")
        return NextGraspChoice(plan, strategy)
    if strategy == "paper":  # its own plan was not fused: the best-scored other
        chosen = int(np.argmax([_planner_score(plan) for plan in alternatives]))
        return NextGraspChoice(alternatives[chosen], strategy, alternatives, (), chosen)
    if strategy == "random":
        chosen = int(rng.integers(len(alternatives)))
        return NextGraspChoice(alternatives[chosen], strategy, alternatives, (), chosen)
    touches = [pad_contacts(plan, grippers[plan.gripper], stage.completed) for plan in alternatives]
    scores = tuple(information_scores(stage, alternatives, grippers, model, earlier, touches))
    # A grasp that would turn the object further than the re-grasp noise lets the estimator
    # follow delivers taxels on a model that no longer stands where they are predicted.
    turn_limit = TURN_SIGMAS * math.sqrt(model.regrasp_noise[0, 0])
    turns = tuple(predicted_turn_rad(touch) for touch in touches)
    followed = np.abs(turns) <= turn_limit
    # A grasp already made is made again only when no other the estimator can follow
    # teaches anything. The floor below stays set by the best grasp the hands deliver, a
    # repeat included: leaving a grasp out for being made already does not make a worse
    # delivered one likelier to hold. Only where no new grasp reaches it does the floor
    # compare the new grasps among themselves.
    repeated = np.array([repeats(plan, earlier, grippers) for plan in alternatives], dtype=bool)
    rated = np.array([delivery(plan) for plan in alternatives]) * followed
    best = rated.max()
    if np.any(followed & ~repeated & (np.asarray(scores) > 0.0)):
        rated = rated * ~repeated
        if not np.any(rated >= PLANNER_FLOOR * best):
            best = rated.max()
    eligible = rated >= PLANNER_FLOOR * best
    expected = np.where(eligible, np.multiply(scores, rated), -1.0)
    if expected.max() <= 0.0:  # none teaches: the best delivered, else the planner's best
        planned = np.array([_planner_score(plan) for plan in alternatives])
        expected = np.where(eligible, rated, -1.0) if rated.max() > 0.0 else planned
    chosen = int(np.argmax(expected))
    return NextGraspChoice(
        alternatives[chosen],
        strategy,
        alternatives,
        scores,
        chosen,
        turns,
        turn_limit,
        tuple(bool(r) for r in repeated),
    )
