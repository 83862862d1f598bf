"""Seeded, serialisable twin scenarios and the hidden truth they produce.

A :class:`TwinScenario` is the *recipe* — which robot, which seed, which payload —
small enough to print in a report and store in JSON.  :func:`make_truth` turns it
into a :class:`TwinTruth`: the true geometry (nominal + hidden errors), true BASE
(robot base in the tracker frame) and PROBE (T-MAC in the flange frame), and the
physical effects of the robot's twin profile (``sim/twin/profiles/<robot>.toml``).

The truth is what a simulated device reads; calibration code never receives it.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from plugcell.io.robot_schema import description_from_dict
from plugcell.io.robots import load_robot
from plugcell.kinematics import GeometricParameters, RobotDescription
from plugcell.kinematics.rotations import rpy_to_matrix
from plugcell.kinematics.transforms import rot_z, translation
from plugcell.sim.twin.generic import generic_twin
from plugcell.sim.twin.physics import Payload, TransmissionError
from plugcell.sim.twin.profile import ScenarioError, TwinProfile, available_profiles

__all__ = ["ScenarioError", "TwinProfile", "TwinScenario", "TwinTruth", "available_profiles",
           "make_truth"]

#: The thesis's payload is mounted "at an offset distance to the centre of the
#: flange surface" (8.2.1, Fig. 8-3): 0.15 m sideways and 0.10 m out.
DEFAULT_PAYLOAD_COM = (0.15, 0.0, 0.10)


@dataclass(frozen=True)
class TwinScenario:
    """Which robot, which hidden errors (by seed), which payload.  JSON-serialisable.

    ``robot``: a shipped robot's name or a description file; ``description``: the
    robot's description itself (:func:`~plugcell.io.robot_schema.description_to_dict`, e.g. from a
    URDF) — then ``robot`` is only its name.
    """

    robot: str = "smart_h4"
    description: dict[str, Any] | None = None
    seed: int = 0
    payload_kg: float = 0.0
    payload_com_m: tuple[float, float, float] = DEFAULT_PAYLOAD_COM
    #: Scale of the hidden geometric errors (1 = the profile's σ; 0 = a perfect robot).
    error_scale: float = 1.0
    #: Switches for the physical effects (all on by default).
    gravity: bool = True
    bending: bool = True
    noise: bool = True
    transmission: bool = True
    backlash: bool = True
    tracker_seed: int | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.payload_kg) and self.payload_kg >= 0):
            raise ScenarioError(f"payload_kg must be ≥ 0, got {self.payload_kg!r}")
        if not (math.isfinite(self.error_scale) and self.error_scale >= 0):
            raise ScenarioError(f"error_scale must be ≥ 0, got {self.error_scale!r}")
        object.__setattr__(self, "payload_com_m", tuple(float(v) for v in self.payload_com_m))

    def to_json(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> TwinScenario:
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ScenarioError(f"scenario is not valid JSON: {exc}") from None
        if not isinstance(d, dict):
            raise ScenarioError("scenario JSON must be an object")
        known = set(cls.__dataclass_fields__)
        unknown = set(d) - known
        if unknown:
            raise ScenarioError(f"unknown scenario keys {sorted(unknown)}; known: {sorted(known)}")
        return cls(**d)

    def with_payload(self, mass_kg: float, com_m: tuple[float, float, float] | None = None
                     ) -> TwinScenario:
        d = asdict(self)
        d["payload_kg"] = float(mass_kg)
        if com_m is not None:
            d["payload_com_m"] = tuple(com_m)
        return TwinScenario(**d)

    @property
    def payload(self) -> Payload:
        return Payload(self.payload_kg, self.payload_com_m)


@dataclass(frozen=True, eq=False)
class TwinTruth:
    """The hidden truth of one simulated robot in its cell (SI units)."""

    description: RobotDescription  # the nominal description (public)
    params: GeometricParameters  # true geometry
    base: np.ndarray  # robot base in the tracker frame (thesis BASE, eq. 6.23)
    probe: np.ndarray  # T-MAC in the flange frame (thesis PROBE)
    stiffness: np.ndarray  # N·m/rad per actuated joint (kinematic joints of a coupling)
    transmission: TransmissionError  # periodic reducer error per motor (joint reading)
    profile: TwinProfile
    scenario: TwinScenario


def _hidden_errors(desc: RobotDescription, profile: TwinProfile, rng: np.random.Generator,
                   scale: float) -> dict[tuple[str, str], float]:
    """Draw the true DH/Hayati errors: every parameter that exists physically.

    Passive joints' θ are set by the closure (no offset); β only where the link is
    Hayati (consecutive parallel axes); the off-chain arm's d and α do not exist
    in the planar loop model (design.md: twists perturb the chain, not the closure).
    """
    loop_arms = {lp.arm for lp in desc.loops}
    errors: dict[tuple[str, str], float] = {}
    for lk in desc.links:
        fields = ["theta", "d", "a", "alpha"]
        if lk.is_passive:
            fields.remove("theta")
        if lk.name in loop_arms:
            fields = [f for f in fields if f in ("theta", "a")]
        if lk.hayati:
            fields.append("beta")
        for f in fields:
            sigma = profile.sigma_length if f in ("d", "a") else profile.sigma_angle
            errors[(lk.name, f)] = scale * sigma * float(rng.standard_normal())
    return errors


def make_truth(scenario: TwinScenario) -> TwinTruth:
    """Build the hidden truth of ``scenario`` (deterministic in its seed)."""
    try:
        desc = (description_from_dict(scenario.description)
                if scenario.description is not None else load_robot(scenario.robot))
    except Exception as exc:  # DescriptionError or unknown robot
        raise ScenarioError(str(exc)) from None
    if desc.name in available_profiles():
        profile = TwinProfile.load(desc.name)
    else:  # a robot without a profile of its own: estimated (sim/twin/generic.py)
        desc, profile = generic_twin(desc)
    if desc.stiffness is None:
        raise ScenarioError(f"robot {desc.name!r} has no joint stiffness in its description")
    rng = np.random.default_rng(scenario.seed)
    params = desc.nominal_parameters().perturbed(
        _hidden_errors(desc, profile, rng, scenario.error_scale)
    )
    tracker_in_robot = translation(np.array(profile.tracker_position)) @ rot_z(profile.tracker_yaw)
    base = np.linalg.inv(tracker_in_robot)
    probe = translation(np.array(profile.probe_position))
    probe[:3, :3] = rpy_to_matrix(*profile.probe_rpy)
    n, k = desc.n_readings, len(profile.transmission_orders)  # one reducer per motor
    scale = profile.transmission_amplitude if scenario.transmission else 0.0
    transmission = TransmissionError(
        profile.transmission_orders,
        np.abs(scale * rng.standard_normal((n, k))),
        rng.uniform(0.0, 2 * np.pi, (n, k)),
    )
    return TwinTruth(desc, params, base, probe, np.array(desc.stiffness), transmission,
                     profile, scenario)
