"""Executing a planned top grasp with a simulated hand, in any physics engine.

Sequence (:func:`execute_grasp`):

1. refuse a refused plan or an opening the hand cannot make (``executed=False``); a plan
   made for another hand is a configuration error;
2. release the object if the hand still holds it from an earlier grasp (open, back off);
3. teleport the open hand to the pre-grasp pose, ``plan.pregrasp_height_m`` above
   ``plan.T_robot_hand`` along +z of frame R; refuse if the hand overlaps the object there;
4. descend to ``plan.T_robot_hand`` at ``descent_speed_m_s`` (the palm's target is moved
   every step), guarded: once the hand bears down on the object with
   ``descent_guard_N`` (the upward part of the contact forces, what a wrist force sensor
   feels; a finger brushing a side does not count), it stops. A finger landing on the
   object means the object reaches further that side than the cloud said (a calibration
   error, a lid wider than the cloud shows), and descending on would shove it aside: the
   hand lifts back to the pre-grasp height, moves the way that finger opens and descends
   again, at most ``reapproaches`` times; the move is ``reapproach_step_m``, halved each
   time the landing finger is on the other side from the last (the room lies in between).
   When the last try lands too, the hand descends on the planned pose unguarded and
   pushes, as a blind hand would.
   Stop with ``executed=False`` if the palm lands or the hand is blocked on the way;
5. close every finger at its own speed (position control with a force cap) until its pads
   report sufficient contact - at least ``min_contact_taxels`` taxels within
   ``contact_gap_m`` of the object (ray probes) and at least ``min_contact_force_N`` summed
   normal force between its pads and the object - or any of its links presses on the
   object with ``blocked_force_N``, or it reaches its joint limit; a finger
   in contact stops, and its joint targets move ``FingerDrive.squeeze`` further in so that
   it presses with its force caps - at once, or, with ``press_together``, only once every
   finger has stopped, and only when every finger is in contact (a guarded close: a
   finger that arrives first waits at the surface instead of pushing the object away from
   the others, and none presses when one closed on nothing); a finger no other closes
   against (the SDH-2's thumb when fingers 1 and 2 pinch across it) stays at the surface
   and does not press (:func:`opposed_fingers`);
6. let everything settle for ``settle_s`` and report.

A grasp that was executed can then be lifted (:func:`lift`): the opposed fingers near the
object press again, the palm rises straight up and holds still, and the object counts as held
when it rose with the hand and lies between the fingers (:func:`held`).

The hand closes along the x axis of ``plan.T_robot_hand`` (``plan.closing_direction`` is
not used here). The object is free: it slides or turns when one finger reaches it before
the others, which is the motion the estimator's bias has to absorb. The true object poses
before and after are read from the simulator. Timestep ``timestep_s`` (default 1/240 s); a
PG-70 grasp takes a few hundred steps.

Both hands close guarded by default (:data:`HAND_GRASP_SETTINGS`): their fingers stop on
proximity (no force needed) and press together. A light object (0.3 kg on friction 0.5
resists 1.5 N; a 170 mm tall, 65 mm thick box tips at 0.7 N pushed near its top) is
otherwise shoved or tipped by the first finger's force before the others arrive - the
SDH-2's 3-4 N flick it tens of millimetres, far outside the bias the estimator can absorb;
the PG-70's 40 N jaws push it to the middle between the pads.
"""

from __future__ import annotations

import math
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from pipeline.errors import ConfigError
from pipeline.sim.hand_models import FingerDrive, SimHand
from pipeline.types import GraspOutcome, GraspPlan, LiftOutcome, ObjectPose


@dataclass(frozen=True)
class GraspSettings:
    """Tunables of :func:`execute_grasp`.

    Attributes:
        timestep_s: physics timestep used during the grasp (restored afterwards).
        descent_speed_m_s: palm speed from the pre-grasp to the grasp pose: slow enough
            that the guard stops a landing within a step (0.4 mm at 1/240 s); three times as
            fast, the landings knocked a tall box over.
        descent_guard_N: upward hand-object contact force that stops the descent (0: the
            descent is not guarded and pushes on).
        reapproaches: times a stopped descent is tried again, moved aside.
        reapproach_step_m: how far the hand moves aside each time, along the direction the
            finger that touched opens: about a camera-to-robot calibration error.
        blocked_tolerance_m: palm position error after the descent that counts as blocked.
        force_fraction: fraction of each joint's URDF effort limit used as its force/torque
            cap while closing (PG-70: 0.2 x 200 N = 40 N per jaw).
        contact_gap_m: a taxel counts as touching within this distance of the object.
        probe_behind_m: contact probe rays start this far behind the pad surface.
        min_contact_taxels: touching taxels a finger needs (over its pads) to stop closing.
        min_contact_force_N: summed pad-object normal force a finger needs to stop closing.
        blocked_force_N: a finger also stops when this much normal force (summed over all
            its links) presses it against the object: it met the object off its pads and
            would only push it.
        check_every_steps: contact is checked every this many physics steps.
        max_close_s: closing gives up after this much simulated time.
        settle_s: simulated time the grasp is held before the final poses are read.
        release_s: time taken to open, and again to back off, when the hand still holds
            the object.
        release_lift_m: how far the palm backs off along its -z when releasing.
        press_together: fingers in contact wait (no squeeze) until every finger has
            stopped, then all press at once; otherwise each presses as soon as it stops.
        lift_speed_m_s: palm speed of :func:`lift`, straight up.
        grip_reach_m: a finger grips in a lift (:func:`lift`) when its pads are within
            this distance of the object.
        lift_slip_m: how far the object may end below the lift's height and still count
            as held (:func:`held`): slipping in the pads and swinging about them, not
            falling.
    """

    timestep_s: float = 1.0 / 240.0
    descent_speed_m_s: float = 0.1
    descent_guard_N: float = 1.0
    reapproaches: int = 3
    reapproach_step_m: float = 0.004
    blocked_tolerance_m: float = 0.005
    force_fraction: float = 0.2
    contact_gap_m: float = 0.001
    probe_behind_m: float = 0.0015
    min_contact_taxels: int = 2
    min_contact_force_N: float = 1.0
    blocked_force_N: float = 2.0
    check_every_steps: int = 2
    max_close_s: float = 2.0
    settle_s: float = 0.15
    release_s: float = 0.2
    release_lift_m: float = 0.05
    press_together: bool = False
    grip_reach_m: float = 0.005
    lift_speed_m_s: float = 0.1
    lift_slip_m: float = 0.02


#: Default settings per hand name (:func:`execute_grasp` falls back to ``GraspSettings()``).
HAND_GRASP_SETTINGS: dict[str, GraspSettings] = {
    "pg70": GraspSettings(min_contact_force_N=0.0, press_together=True),
    "sdh": GraspSettings(min_contact_force_N=0.0, press_together=True),
}


class Physics(Protocol):
    """The engine's side of a grasp: the scene the hand and the object are in.

    Attributes:
        object_id: the grasped body, in the engine's ids (what the hand's contact and
            probe methods take).
    """

    object_id: int

    def step(self, steps: int = 1) -> None:
        """Advance the physics by ``steps`` time steps."""

    def detect_collisions(self) -> None:
        """Update the contacts for the current poses without stepping."""

    def object_pose(self) -> ObjectPose:
        """The object's true pose (its mesh frame in frame R)."""

    def timestep(self, timestep_s: float) -> AbstractContextManager[None]:
        """Use ``timestep_s`` inside the block, the previous time step after it."""


def _outcome(
    physics: Physics,
    hand: SimHand,
    before: ObjectPose,
    executed: bool,
    reason: str = "",
    reapproaches: int = 0,
) -> GraspOutcome:
    return GraspOutcome(
        executed=executed,
        reapproaches=reapproaches,
        aperture_m=hand.aperture() if executed else math.nan,
        joint_positions=hand.joint_positions(),
        T_robot_hand=hand.pose(),
        object_before=before,
        object_after=physics.object_pose(),
        reason=reason,
    )


def _release(physics: Physics, hand: SimHand, opening_m: float, settings: GraspSettings) -> None:
    """Open the fingers with the palm held still, then back the palm off along -z of the
    hand: fingers that open while the palm rises drag the object along by their pads'
    friction (a box slid by a centimetre and turned by degrees). Only the joints that close
    the fingers open; the others (the SDH-2's spread) stay where the grasp put them, since
    turning the fingers about the object sweeps it aside (a cylinder by 40 mm)."""
    closing = {joint for finger in hand.model.fingers for joint in finger.joints}
    held = hand.joint_positions()
    hand.command(
        {
            name: value if name in closing else held[name]
            for name, value in hand.open_configuration(opening_m).items()
        }
    )
    T_robot_hand = hand.pose()
    steps = max(1, round(settings.release_s / settings.timestep_s))
    for _ in range(steps):
        hand.move_to(T_robot_hand)
        physics.step()
    for step in range(1, steps + 1):
        target = T_robot_hand.copy()
        target[:3, 3] -= T_robot_hand[:3, 2] * settings.release_lift_m * step / steps
        hand.move_to(target)
        physics.step()


def release(
    physics: Physics,
    hand: SimHand,
    opening_m: float,
    settings: GraspSettings | None = None,
) -> ObjectPose:
    """Open the hand to ``opening_m``, back it off, let the object settle for
    ``settings.settle_s`` and park the hand out of sight; the object's pose then.

    A hand that touches nothing is parked at once.
    """
    s = settings or HAND_GRASP_SETTINGS.get(hand.spec.name, GraspSettings())
    with physics.timestep(s.timestep_s):
        if hand.touches(physics.object_id):
            _release(physics, hand, opening_m, s)
        hand.park()
        physics.step(max(1, round(s.settle_s / s.timestep_s)))
    return physics.object_pose()


def _finger_targets(
    hand: SimHand, open_targets: dict[str, float], closure: np.ndarray, touching: np.ndarray
) -> dict[str, float]:
    targets = dict(open_targets)
    for i, finger in enumerate(hand.model.fingers):
        for joint, ratio, squeeze in zip(finger.joints, finger.ratios, finger.squeeze, strict=True):
            targets[joint] = open_targets[joint] + ratio * closure[i] + squeeze * touching[i]
    return targets


def opposed_fingers(facings: np.ndarray) -> np.ndarray:
    """``(F,)`` whether each finger, closing along its row of ``facings`` (unit, palm xy),
    has another closing against it: one at least 120 deg away (the tripod's fingers
    oppose each other). A finger nothing opposes only pushes the object when it presses."""
    facings = np.asarray(facings, dtype=np.float64)
    dots = facings @ facings.T
    np.fill_diagonal(dots, 1.0)
    return dots.min(axis=1) <= -0.5 + 1e-9


def _close(
    physics: Physics,
    hand: SimHand,
    open_targets: dict[str, float],
    spread_rad: float,
    s: GraspSettings,
) -> None:
    """Close every finger until it touches (or reaches its limit); see the module doc."""
    fingers = hand.model.fingers
    presses = opposed_fingers(hand.model.facings(spread_rad)).astype(np.float64)
    closure = np.zeros(len(fingers))
    limit = np.array([hand.closure_limit(f, open_targets) for f in fingers])
    stopped = limit <= 0.0
    touching = np.zeros(len(fingers))  # pressing now
    contact = np.zeros(len(fingers))  # stopped at the surface
    pad_row = {pad: i for i, pad in enumerate(hand.pad_ids)}
    for step in range(round(s.max_close_s / s.timestep_s)):
        closure = np.where(
            stopped,
            closure,
            np.minimum(closure + s.timestep_s * np.array([f.speed for f in fingers]), limit),
        )
        hand.command(_finger_targets(hand, open_targets, closure, touching), s.force_fraction)
        physics.step()
        if step % s.check_every_steps:
            continue
        frames, gaps = hand.taxel_gaps(physics.object_id, s.probe_behind_m, s.contact_gap_m)
        touched_pads = frames.pads[gaps <= s.contact_gap_m]
        forces = hand.pad_contact_forces(physics.object_id)
        blocking = hand.finger_contact_forces(physics.object_id)
        for i, finger in enumerate(fingers):
            if stopped[i]:
                continue
            taxels = int(np.isin(touched_pads, finger.pads).sum())
            force = forces[[pad_row[p] for p in finger.pads]].sum()
            touched = taxels >= s.min_contact_taxels and force >= s.min_contact_force_N
            if touched or blocking[i] >= s.blocked_force_N:
                stopped[i] = True
                contact[i] = 1.0
                if not s.press_together:
                    touching[i] = presses[i]
            elif closure[i] >= limit[i]:
                stopped[i] = True
        if stopped.all():
            break
    if s.press_together and not contact.all():
        # A finger closed on nothing: pressing with the others would only shove the object.
        contact[:] = 0.0
    hand.command(_finger_targets(hand, open_targets, closure, contact * presses), s.force_fraction)


def execute_grasp(
    physics: Physics,
    hand: SimHand,
    plan: GraspPlan,
    settings: GraspSettings | None = None,
) -> GraspOutcome:
    """Run a planned grasp on ``physics.object_id`` and report what happened (module
    docstring).

    Args:
        physics: the engine's scene (its world frame is frame R).
        hand: the hand, loaded into that scene.
        plan: the grasp; ``T_robot_hand`` is the palm pose at the grasp.
        settings: tunables; defaults to the hand's :data:`HAND_GRASP_SETTINGS` entry.

    Raises:
        ConfigError: the plan was made for a different hand.
    """
    s = settings or HAND_GRASP_SETTINGS.get(hand.spec.name, GraspSettings())
    before = physics.object_pose()
    if plan.gripper != hand.spec.name:
        raise ConfigError(
            f"grasp plan is for gripper '{plan.gripper}' but the world's hand is '{hand.spec.name}'"
        )
    if plan.status != "ok":
        return _outcome(physics, hand, before, False, plan.reason or "plan refused")
    try:
        open_targets = hand.open_configuration(plan.opening_m, plan.spread_rad)
    except ValueError as error:
        return _outcome(physics, hand, before, False, f"cannot open: {error}")

    with physics.timestep(s.timestep_s):
        return _execute(physics, hand, plan, open_targets, before, s)


def _execute(
    physics: Physics,
    hand: SimHand,
    plan: GraspPlan,
    open_targets: dict[str, float],
    before: ObjectPose,
    s: GraspSettings,
) -> GraspOutcome:
    """Steps 2-6 of the module docstring, at the settings' timestep."""
    if hand.touches(physics.object_id):
        _release(physics, hand, plan.opening_m, s)
        before = physics.object_pose()

    T_grasp = np.asarray(plan.T_robot_hand, dtype=np.float64).copy()
    facings = hand.model.facings(plan.spread_rad)
    reapproaches, step_m, previous, guard_N = 0, s.reapproach_step_m, None, s.descent_guard_N

    def not_executed(reason: str) -> GraspOutcome:
        return _outcome(physics, hand, before, False, reason, reapproaches)

    while True:
        T_pregrasp = T_grasp.copy()
        T_pregrasp[2, 3] += plan.pregrasp_height_m
        hand.set_opening(plan.opening_m, plan.spread_rad)
        hand.reset_pose(T_pregrasp)
        physics.detect_collisions()
        if hand.touches(physics.object_id):
            return not_executed("hand overlaps the object at the pre-grasp pose")
        if not _move_palm(physics, hand, T_pregrasp, T_grasp, guard_N, s):
            break
        finger, _ = hand.bearing_down(physics.object_id)
        if finger is None:
            return not_executed(
                "the palm met the object during the descent, "
                f"{1e3 * (hand.pose()[2, 3] - T_grasp[2, 3]):.0f} mm above the grasp pose"
            )
        stopped = hand.pose()
        stopped[:3, :3] = T_grasp[:3, :3]
        lifted = stopped.copy()
        lifted[2, 3] = T_pregrasp[2, 3]
        _move_palm(physics, hand, stopped, lifted, 0.0, s)
        if reapproaches == s.reapproaches:
            # Every place tried lands on the object: descend on the plan, as a blind hand
            # would, and push.
            T_grasp, guard_N = np.asarray(plan.T_robot_hand, dtype=np.float64).copy(), 0.0
            continue
        # The finger opens against its facing; the object reaches further that way.
        outward = -(T_grasp[:3, :2] @ facings[finger])
        outward /= np.linalg.norm(outward)
        if previous is not None and outward @ previous < 0.0:
            step_m /= 2.0  # the other side landed now: the room lies in between
        T_grasp[:3, 3] += step_m * outward
        previous = outward
        reapproaches += 1
    physics.step(2)
    miss_m = float(np.linalg.norm(hand.pose()[:3, 3] - T_grasp[:3, 3]))
    if miss_m > s.blocked_tolerance_m:
        return not_executed(
            f"hand blocked {miss_m * 1e3:.1f} mm short of the grasp pose during the descent"
        )

    _close(physics, hand, open_targets, plan.spread_rad, s)
    physics.step(max(1, round(s.settle_s / s.timestep_s)))
    return _outcome(physics, hand, before, True, "", reapproaches)


def _move_palm(
    physics: Physics,
    hand: SimHand,
    T_from: np.ndarray,
    T_to: np.ndarray,
    guard_N: float,
    s: GraspSettings,
) -> bool:
    """Move the palm in a straight line from ``T_from`` to ``T_to`` (same orientation) at
    ``descent_speed_m_s``; True when the hand bore down on the object with ``guard_N`` on
    the way and stopped (0: no guard)."""
    travel = T_to[:3, 3] - T_from[:3, 3]
    steps = max(1, math.ceil(np.linalg.norm(travel) / (s.descent_speed_m_s * s.timestep_s)))
    for step in range(1, steps + 1):
        target = T_to.copy()
        target[:3, 3] = T_from[:3, 3] + travel * step / steps
        hand.move_to(target)
        physics.step()
        if guard_N > 0.0 and hand.bearing_down(physics.object_id)[1] >= guard_N:
            return True
    return False


def held(rise_m: float, height_m: float, fingers_touching: int, slip_m: float) -> bool:
    """Whether a lift of ``height_m`` held the object: it rose at least ``height_m -
    slip_m`` (it went up with the hand and did not fall or slide out; the table is
    ``height_m`` below) and at least two fingers still touch it (it lies between them;
    an object hanging on one finger, or balanced on the palm, is not held)."""
    return rise_m >= height_m - slip_m and fingers_touching >= 2


#: Two fingers near the object oppose each other in a grip when the mean normals of
#: their near taxels have at most this cosine (about 105 deg apart): the SDH-2's tripod
#: (120 deg) and the PG-70's jaws (180 deg) grip, the thumb beside a pinch of fingers 1
#: and 2 across it (90 deg to both) does not; measured normals leave a tripod just short
#: of :func:`opposed_fingers`'s 120 deg.
GRIP_OPPOSED_COS = -0.25


def gripping_fingers(hand: SimHand, object_id: int, s: GraspSettings) -> list[FingerDrive]:
    """The fingers that grip in a lift: those within ``grip_reach_m`` of the object (their
    taxel probes) that another such finger opposes (the mean normals of their near taxels
    :data:`GRIP_OPPOSED_COS` apart about the vertical); none when no two oppose, as in
    the grasp's press (:func:`_close`): a finger pressing alone only pushes the object."""
    frames, gaps = hand.taxel_gaps(object_id, s.probe_behind_m, s.grip_reach_m)
    near = gaps <= s.grip_reach_m
    fingers, facings = [], []
    for finger in hand.model.fingers:
        facing = frames.normals[near & np.isin(frames.pads, finger.pads), :2].sum(axis=0)
        if np.linalg.norm(facing) > 0.0:
            fingers.append(finger)
            facings.append(facing / np.linalg.norm(facing))
    if len(fingers) < 2:
        return []
    dots = np.array(facings) @ np.array(facings).T
    np.fill_diagonal(dots, 1.0)
    return [f for f, cos in zip(fingers, dots.min(axis=1), strict=True) if cos <= GRIP_OPPOSED_COS]


def _grip(hand: SimHand, fingers: list[FingerDrive], s: GraspSettings) -> None:
    """Press ``fingers`` again as the lift starts: each joint's target its squeeze
    (``FingerDrive.squeeze``) beyond where it is now, under its force cap. The grasp's
    press set the targets a squeeze past the first touch; an object that then turned
    square in the pads (a box grasped 15 deg off its faces) was left untouched by them.
    Pressing every step instead would roll the SDH-2's distal links on along the
    surface until they let go."""
    if not fingers:
        return
    targets = hand.joint_positions()
    for finger in fingers:
        for joint, squeeze in zip(finger.joints, finger.squeeze, strict=True):
            targets[joint] += squeeze
    hand.command(targets, s.force_fraction)


def lift(
    physics: Physics,
    hand: SimHand,
    height_m: float,
    hold_s: float,
    settings: GraspSettings | None = None,
) -> LiftOutcome:
    """Press the :func:`gripping_fingers` again (:func:`_grip`), raise the palm
    ``height_m`` straight up (+z of frame R) at ``lift_speed_m_s``, hold it still for
    ``hold_s`` and report whether the object is still held (:func:`held`). A hand that
    holds nothing rises all the same; the object then stays on the table (not held)."""
    s = settings or HAND_GRASP_SETTINGS.get(hand.spec.name, GraspSettings())
    before = physics.object_pose()
    T_start = hand.pose()
    fingers = gripping_fingers(hand, physics.object_id, s)
    rise_steps = max(1, math.ceil(height_m / (s.lift_speed_m_s * s.timestep_s)))
    hold_steps = max(1, round(hold_s / s.timestep_s))
    _grip(hand, fingers, s)
    with physics.timestep(s.timestep_s):
        for step in range(1, rise_steps + hold_steps + 1):
            target = T_start.copy()
            target[2, 3] += height_m * min(step, rise_steps) / rise_steps
            hand.move_to(target)
            physics.step()
    after = physics.object_pose()
    touching = int((hand.finger_contact_forces(physics.object_id) > 0.0).sum())
    rise_m = float(after.position_m[2] - before.position_m[2])
    return LiftOutcome(
        held=held(rise_m, height_m, touching, s.lift_slip_m),
        rise_m=rise_m,
        hand_rise_m=float(hand.pose()[2, 3] - T_start[2, 3]),
        fingers_touching=touching,
        object_before=before,
        object_after=after,
    )
