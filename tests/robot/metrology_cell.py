"""The metrology cell of the program-library tests (thesis 8.2–8.4): real processes.

CAMERA and TOOL (for the EXAMPLE), the simulated TRACKER, COMPUTE, the Smart H4
``H4`` carrying 36 kg and the elbow robot ``KUKA``, each with its simulated
controller, started once and wired robot → partners.  The tests know the twins'
hidden truth only to give the programs what appendix D would (BASE and PROBE
estimates) and to judge the results.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from robot_cell import Launcher

from plugcell.devices.robot.value_text import numbers_text
from plugcell.framework import BlockingClient, ProcessStates, from_data
from plugcell.io.units import robot_from_pose
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario

#: Simulated seconds per real second of the robots; the tracker keeps the same clock.
SPEED = 100.0
H4 = dict(name="H4", robot="smart_h4", seed=4, payload_kg=36.0)
KUKA = dict(name="KUKA", robot="elbow6", seed=5, payload_kg=0.0)
PARTNERS = {"H4": ("CAMERA", "TOOL", "TRACKER", "COMPUTE"), "KUKA": ("TRACKER", "COMPUTE")}


@dataclass
class RobotInCell:
    """One simulated robot of the cell: its twin (same scenario as its controller's)."""

    name: str
    twin: RobotTwin

    @classmethod
    def of(cls, spec: dict) -> RobotInCell:
        return cls(spec["name"], RobotTwin(TwinScenario(robot=spec["robot"], seed=spec["seed"],
                                                        payload_kg=spec["payload_kg"])))

    def estimates(self, rng: np.random.Generator) -> tuple[str, str]:
        """BASE and PROBE as appendix D would give them: the truth within ~1 mm, 0.03°."""
        truth = self.twin.reveal_truth()
        base = robot_from_pose(truth.base, "zyz") + np.r_[rng.normal(0, 0.7, 3),
                                                              rng.normal(0, 0.02, 3)]
        probe = robot_from_pose(truth.probe, "zyz") + np.r_[rng.normal(0, 0.4, 3),
                                                                rng.normal(0, 0.02, 3)]
        return numbers_text(base), numbers_text(probe)


class MetrologyCell:
    """The running cell and a client."""

    def __init__(self, launcher: Launcher, client: BlockingClient) -> None:
        self.launcher = launcher
        self.client = client
        self.cell = launcher.cell
        self.home = launcher.home
        self.h4 = RobotInCell.of(H4)
        self.kuka = RobotInCell.of(KUKA)

    @staticmethod
    def start(launcher: Launcher) -> list:
        procs = [
            launcher.serve("camera", "--param", "time_scale=0.001"),
            launcher.serve("drill", "--param", "time_scale=0.001"),
            launcher.serve("tracker", "--param", "seed=7", "--param", f"time_scale={1 / SPEED}"),
            launcher.serve("compute"),
        ]
        for spec in (H4, KUKA):
            procs.append(launcher.serve(
                "robot", "--param", "sim=true", "--param", f"speed={SPEED:g}",
                "--param", f"robot={spec['robot']}", "--param", f"seed={spec['seed']}",
                "--param", f"payload_kg={spec['payload_kg']}", "--param", "link_baud=19200",
                name=spec["name"]))
        return procs

    def wire(self) -> None:
        for name in ("CAMERA", "TOOL", "TRACKER", "COMPUTE", "H4", "KUKA"):
            assert self.client.wait_for(name, 20.0), f"{name} not seen"
        for robot, partners in PARTNERS.items():
            for partner in partners:
                response = self.client.ask_subscribe(robot, partner)
                assert response.ok, response.reason

    def activate(self, robot: str, program: str, *values: str, wait: bool = True,
                 timeout: float = 120.0):
        call = self.client.create_process(robot, "ACTIVATE", "Wait" if wait else "",
                                          [program, *values], timeout=timeout)
        return call if not wait else call.result()

    def status(self, robot: str) -> list[str]:
        final = self.client.create_process(robot, "PROGRAM_STATUS").result()
        assert final.state is ProcessStates.Completed, final.reason
        return [str(s) for s in from_data(final.data).reshape(-1)]

    def evaluate(self, expression: str) -> None:
        final = self.client.create_process("COMPUTE", "Evaluate", "", expression,
                                           timeout=120).result()
        assert final.state is ProcessStates.Completed, final.reason

    def matrix(self, name: str) -> np.ndarray:
        final = self.client.create_process("COMPUTE", "Get Matrix", name).result()
        assert final.state is ProcessStates.Completed, final.reason
        return np.asarray(from_data(final.data), dtype=float)
