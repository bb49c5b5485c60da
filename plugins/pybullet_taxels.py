"""Per-taxel tactile model for the PyBullet world: one probing ray along each taxel normal."""

from __future__ import annotations

from dataclasses import dataclass

from pipeline import hookimpl
from pipeline.errors import ConfigError, PluginError
from pipeline.params import param
from pipeline.stages import TactileModel, World
from pipeline.types import Contacts, GraspOutcome


class PybulletTaxels(TactileModel):
    """Taxel contacts from batched ray probes along each taxel normal (PyBullet world only).

    Every taxel of every pad casts one ray along its outward normal, from ``ray_behind_m``
    behind the pad surface to ``ray_length_m`` past it (one ``rayTestBatch`` for the whole
    hand, the hand itself excluded). A taxel reports contact when the first thing its ray
    hits is the object, no farther than ``contact_threshold_m`` beyond the pad surface
    (surfaces pressed into the pad always count). Reported positions are the taxel centres
    and normals from forward kinematics of the hand's current configuration, in frame R,
    optionally with isotropic Gaussian position noise; each contact taxel is independently
    dropped with ``dead_taxel_probability``. Randomness comes from ``world.rng``.

    Needs a world with ``client`` (PyBullet client id), ``hand``
    (:class:`pipeline.sim.hands.Hand`) and ``object_id``, as ``PybulletWorld`` has.
    """

    name = "pybullet-taxels"

    @dataclass(frozen=True)
    class Params:
        contact_threshold_m: float = param(
            0.001,
            "contact when the object is at most this far past the pad surface (m)",
            at_least=0.0,
        )
        ray_behind_m: float = param(
            0.0015, "rays start this far behind the pad surface, inside the pad (m)", at_least=0.0
        )
        ray_length_m: float = param(
            0.005, "rays reach this far past the pad surface; >= contact_threshold_m (m)"
        )
        position_noise_std_m: float = param(
            0.0,
            "std of isotropic Gaussian noise added to each reported taxel position (m)",
            at_least=0.0,
        )
        dead_taxel_probability: float = param(
            0.0, "probability that a taxel in contact reports nothing (per taxel, per read)"
        )

    def __init__(self, params: Params | None = None) -> None:
        super().__init__(params)
        p = self.params
        key = f"tactile.{self.name}"
        if p.ray_length_m < p.contact_threshold_m:
            raise ConfigError(
                f"config key '{key}.ray_length_m' ({p.ray_length_m}) must be >= "
                f"contact_threshold_m ({p.contact_threshold_m})"
            )
        if not 0.0 <= p.dead_taxel_probability <= 1.0:
            raise ConfigError(f"config key '{key}.dead_taxel_probability' must be within [0, 1]")

    def read(self, world: World, outcome: GraspOutcome) -> Contacts:
        """Taxels touching the object now, in frame R (``outcome`` is not needed: the
        hand's current state is what the sensors see)."""
        hand = getattr(world, "hand", None)
        if hand is None or not hasattr(world, "client") or not hasattr(world, "object_id"):
            raise PluginError(
                f"tactile model '{self.name}' needs a PyBullet world with client, hand and "
                f"object_id; got {type(world).__name__}"
            )
        p = self.params
        frames, gaps = hand.taxel_gaps(world.object_id, p.ray_behind_m, p.ray_length_m)
        keep = gaps <= p.contact_threshold_m
        if p.dead_taxel_probability > 0.0:
            keep &= world.rng.random(len(keep)) >= p.dead_taxel_probability
        positions = frames.positions[keep]
        if p.position_noise_std_m > 0.0:
            positions = positions + world.rng.normal(0.0, p.position_noise_std_m, positions.shape)
        return Contacts(
            positions=positions,
            normals=frames.normals[keep],
            pads=frames.pads[keep],
            taxel_indices=frames.taxel_indices[keep],
        )


@hookimpl
def symfuse_register_stages(registry):
    registry.add(PybulletTaxels)
