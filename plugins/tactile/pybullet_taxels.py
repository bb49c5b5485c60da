"""Built-in tactile model ``pybullet-taxels``: a taxel is in contact when the object is within
a threshold of its surface along its normal."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from pipeline.api import ConfigError, Contacts, GraspOutcome, TactileModel, World, hookimpl, param


class PybulletTaxels(TactileModel):
    """Taxel contacts from the object's distance along each taxel normal (any world).

    Asks the world for every taxel of its hand with the object's signed distance along the
    taxel's outward normal, probed from ``ray_behind_m`` behind the pad surface to
    ``ray_length_m`` past it (the PyBullet world casts one ray per taxel, the hand itself
    excluded). A taxel reports contact when the object is the first thing along that
    probe, no farther than ``contact_threshold_m`` beyond the pad surface (surfaces pressed
    into the pad always count). Reported positions are the taxel centres and normals of
    the hand's current configuration, in frame R, optionally with isotropic Gaussian
    position noise; each contact taxel is independently dropped with
    ``dead_taxel_probability``. Randomness comes from ``world.rng``. (The name is kept from
    when it needed the PyBullet world.)
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
            0.005,
            "rays reach this far past the pad surface; >= contact_threshold_m (m)",
            at_least=0.0,
        )
        position_noise_std_m: float = param(
            0.0,
            "std of isotropic Gaussian noise added to each reported taxel position (m)",
            at_least=0.0,
        )
        dead_taxel_probability: float = param(
            0.0,
            "probability that a taxel in contact reports nothing (per taxel, per read)",
            at_least=0.0,
            at_most=1.0,
        )

    @classmethod
    def check_params(cls, params: Params) -> None:
        super().check_params(params)
        p = params
        key = f"tactile.{cls.name}"
        if p.ray_length_m < p.contact_threshold_m:
            raise ConfigError(
                f"config key '{key}.ray_length_m' ({p.ray_length_m}) must be >= "
                f"contact_threshold_m ({p.contact_threshold_m})"
            )

    def read(self, world: World, outcome: GraspOutcome) -> Contacts:
        """Taxels touching the object now, in frame R (``outcome`` is not needed: the
        hand's current state is what the sensors see)."""
        p = self.params
        taxels = world.taxels(p.ray_behind_m, p.ray_length_m)
        keep = taxels.gaps_m <= p.contact_threshold_m
        if p.dead_taxel_probability > 0.0:
            keep &= world.rng.random(len(keep)) >= p.dead_taxel_probability
        contacts = taxels.contacts(keep)
        if p.position_noise_std_m > 0.0:
            noise = world.rng.normal(0.0, p.position_noise_std_m, contacts.positions.shape)
            contacts = dataclasses.replace(contacts, positions=contacts.positions + noise)
        return contacts


@hookimpl
def symfuse_register_stages(registry):
    registry.add(PybulletTaxels)
