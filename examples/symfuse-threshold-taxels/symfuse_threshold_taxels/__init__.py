"""symfuse plugin: taxels that respond only above a force, and a seeded set of dead taxels.

Real tactile arrays have a response threshold (a light touch reads as nothing) and, with
wear, taxels that never respond. This tactile model adds both to the geometric contact
test of the built-in model, using only the world contract: ``world.taxels`` gives every
taxel's distance to the object along its normal and the normal force on its pad.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.api import (
    Contacts,
    GraspOutcome,
    TactileModel,
    World,
    hookimpl,
    param,
)


def taxel_forces(pads: np.ndarray, pad_forces_N: np.ndarray, touching: np.ndarray) -> np.ndarray:
    """Each touching taxel's share of its pad's force (N): the pad's force split evenly over
    the pad's touching taxels; 0 for a taxel that does not touch.

    Args:
        pads: ``(N,)`` pad id of each taxel.
        pad_forces_N: ``(N,)`` normal force on each taxel's pad (N).
        touching: ``(N,)`` bool, the taxels within the contact gap.
    """
    forces = np.zeros(len(pads))
    for pad in np.unique(pads[touching]):
        on_pad = touching & (pads == pad)
        forces[on_pad] = pad_forces_N[on_pad] / on_pad.sum()
    return forces


class ThresholdTaxels(TactileModel):
    """Taxels that respond above a force threshold; a seeded fraction of them is dead.

    A taxel is in contact when the object is at most ``contact_gap_m`` past its surface
    (pressed in always counts) and its share of its pad's normal force is at least
    ``min_taxel_force_N``. ``dead_fraction`` of the taxels never respond; which ones is
    drawn once from ``dead_seed`` over the world's (fixed) taxel order, so the same taxels
    are dead in every grasp.
    """

    name = "threshold-taxels"

    @dataclass(frozen=True)
    class Params:
        contact_gap_m: float = param(
            0.001, "object at most this far past the pad surface touches (m)", at_least=0.0
        )
        probe_behind_m: float = param(
            0.0015, "probe from this far behind the pad surface (m)", at_least=0.0
        )
        min_taxel_force_N: float = param(
            0.05, "a touching taxel responds from this share of its pad's force (N)", at_least=0.0
        )
        dead_fraction: float = param(
            0.0, "fraction of taxels that never respond", at_least=0.0, at_most=1.0
        )
        # Which taxels are dead is a property of this (worn) sensor, the same in every
        # trial, so it has its own seed rather than the world's generator.
        dead_seed: int = param(0, "seed of which taxels are dead", at_least=0)

    def read(self, world: World, outcome: GraspOutcome) -> Contacts:
        """The responding taxels now, in frame R (``outcome`` is not needed: what the
        taxels feel is the hand's current state)."""
        p = self.params
        state = world.taxels(p.probe_behind_m, p.contact_gap_m)
        touching = state.gaps_m <= p.contact_gap_m
        forces = taxel_forces(state.pads, state.pad_forces_N, touching)
        alive = np.random.default_rng(p.dead_seed).random(len(state)) >= p.dead_fraction
        return state.contacts(touching & (forces >= p.min_taxel_force_N) & alive)


@hookimpl
def symfuse_register_stages(registry):
    registry.add(ThresholdTaxels)
