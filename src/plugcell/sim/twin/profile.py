"""The physics a robot's twin has beyond its description: its twin profile.

The shipped robots' profiles are ``sim/twin/profiles/<robot>.toml`` (docs/twin.md);
:func:`plugcell.sim.twin.generic.generic_twin` estimates one for any other robot.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from importlib import resources

from plugcell.sim.twin.physics import Beam


class ScenarioError(ValueError):
    """A scenario that cannot be built (unknown robot, no twin profile, bad value)."""


@dataclass(frozen=True)
class TwinProfile:
    """The physics a robot's twin has beyond its description (see ``docs/twin.md``)."""

    robot: str
    sigma_length: float  # m
    sigma_angle: float  # rad
    encoder_resolution: float  # rad
    repeatability: float  # rad, 1-σ per joint and move
    lost_motion: float  # rad, backlash of each reducer
    preload_torque: float  # N·m: gravity above this holds the gear on one flank
    transmission_orders: tuple[int, ...]
    transmission_amplitude: float  # rad, 1-σ of each harmonic's amplitude
    beams: tuple[Beam, ...]
    tracker_position: tuple[float, float, float]
    tracker_yaw: float  # rad
    probe_position: tuple[float, float, float]
    probe_rpy: tuple[float, float, float]  # rad
    reference_zyz: tuple[float, float, float]  # rad
    spread: float  # rad

    @classmethod
    def load(cls, robot: str) -> TwinProfile:
        """The packaged profile ``sim/twin/profiles/<robot>.toml``."""
        try:
            profiles = resources.files("plugcell.sim.twin").joinpath("profiles")
            text = profiles.joinpath(f"{robot}.toml").read_text()
        except FileNotFoundError:
            raise ScenarioError(
                f"no twin profile for robot {robot!r}; available: {available_profiles()}"
            ) from None
        d = tomllib.loads(text)
        rad = math.radians
        try:
            g, j, c, p = d["geometric_errors"], d["joints"], d["cell"], d["poses"]
            return cls(
                robot=d["robot"],
                sigma_length=g["sigma_length_mm"] * 1e-3,
                sigma_angle=rad(g["sigma_angle_deg"]),
                encoder_resolution=rad(j["encoder_resolution_deg"]),
                repeatability=rad(j["repeatability_deg"]),
                lost_motion=rad(j["lost_motion_deg"]),
                preload_torque=float(j["preload_torque_nm"]),
                transmission_orders=tuple(int(k) for k in j["transmission_orders"]),
                transmission_amplitude=rad(j["transmission_amplitude_deg"]),
                beams=tuple(Beam(b["link"], b["carries"], float(b["compliance"]))
                            for b in d.get("bending", [])),
                tracker_position=tuple(c["tracker_position_m"]),
                tracker_yaw=rad(c["tracker_yaw_deg"]),
                probe_position=tuple(c["probe_position_m"]),
                probe_rpy=tuple(rad(v) for v in c["probe_rpy_deg"]),
                reference_zyz=tuple(rad(v) for v in p["reference_zyz_deg"]),
                spread=rad(p["spread_deg"]),
            )
        except KeyError as exc:  # a packaged file: a bug, but say which key
            raise ScenarioError(f"twin profile {robot!r} lacks the key {exc}") from None


def available_profiles() -> list[str]:
    root = resources.files("plugcell.sim.twin").joinpath("profiles")
    return sorted(p.name.removesuffix(".toml") for p in root.iterdir() if p.name.endswith(".toml"))
