"""The robot service over KUKA RSI and ABB EGM (issue 37 §1, §5, §6): the program runs on
the PC, each move streams to the twin's robot side (its own process, a KUKA controller
over UDP as absolute joint corrections, or an ABB controller's EGMRunJoint as joint
targets); joint feedback is the packets' actual joints (AIPos, feedBack.joints).  Each
test runs over both.

* two PTPs and a LIN end Completed with the twin at the last move's end (within the
  following error);
* an unreachable move and one beyond the joint limits end Failed naming the program line,
  the move and why — and the robot is still there;
* killing the twin's robot side fails the running process within one controller timeout,
  and the service comes back Online (and runs programs again) when the robot streams again;
* bad options are refused with the reason.
"""

from __future__ import annotations

import asyncio
import dataclasses
import shutil
import time
from pathlib import Path

import numpy as np
import pytest
from robot_testlib import start_with_controller, unique_cell

from plugcell.apps.kinds import build
from plugcell.devices.robot.service import RobotService
from plugcell.framework import Client, GenericDevice, ProcessStates
from plugcell.framework.data import from_data
from plugcell.framework.messages import ConnectionStates
from plugcell.sim.controller.egm_twin import EgmTwinProcess
from plugcell.sim.controller.rsi_twin import RsiTwinProcess
from plugcell.sim.ports import free_port

#: The controller timeout of these tests: RSI's ETHERNET Timeout (packets of 4 ms; the twin
#: counts every late answer, and this machine is shared — 1000 leaves room) and EGM's
#: \CommTimeout, both 4 s.
TIMEOUT = 1000
TIMEOUT_S = TIMEOUT * 0.004


@dataclasses.dataclass(frozen=True)
class Vendor:
    """How a test reaches the robot over one interface."""

    name: str
    twin: type
    twin_options: tuple[str, ...]
    timeout: dict

    def service_params(self, port: int) -> dict:
        return {self.name.lower(): f"127.0.0.1:{port}", **self.timeout}

    def robot(self, port: int):
        return self.twin(f"127.0.0.1:{port}", *self.twin_options)


VENDORS = [Vendor("RSI", RsiTwinProcess, ("--timeout", str(TIMEOUT)),
                  {"rsi_timeout": TIMEOUT}),
           Vendor("EGM", EgmTwinProcess, ("--timeout", str(TIMEOUT_S)),
                  {"egm_timeout": TIMEOUT_S})]

MOVES = """\
PROGRAM rsimoves
VAR p : POSITION
BEGIN
  MOVE TO JNTP(5, -85, -185, 0, 85, 5)
  MOVE TO JNTP(10, -80, -182, 5, 80, 10)
  p := ARM_POS
  p := POS(p.x + 50, p.y, p.z - 30, p.a, p.b, p.c)
  MOVE LINEAR TO p
  WRITE LUN_CRT ('done')
END rsimoves
"""

REFUSED = """\
PROGRAM {name}
BEGIN
  MOVE TO JNTP(2, -88, -186, 0, 88, 2)
  MOVE TO {target}
END {name}
"""

F, C = ProcessStates.Failed, ProcessStates.Completed


@pytest.fixture
def library(tmp_path: Path) -> Path:
    lib = tmp_path / "programs"
    lib.mkdir()
    (lib / "rsimoves.pdl").write_text(MOVES)
    (lib / "unreachable.pdl").write_text(REFUSED.format(
        name="unreachable", target="POS(4000, 0, 1000, 0, 90, 0)"))
    (lib / "beyond.pdl").write_text(REFUSED.format(
        name="beyond", target="JNTP(0, -90, -187, 0, 90, 400)"))
    shutil.copy(Path(__file__).parent / "programs" / "swing.pdl", lib)
    return lib


def _service(vendor: Vendor, port: int, library: Path, cell: str,
             tmp_path: Path) -> GenericDevice:
    service = build("robot", None, {**vendor.service_params(port), "library": str(library)},
                    cell=cell, journal=tmp_path / "journal")
    assert isinstance(service.interface, RobotService)
    return service


async def _run(client: Client, name: str, program: str, timeout: float = 60.0):
    call = await client.create_process(name, "ACTIVATE", "Wait", [program], timeout=timeout)
    return await call.result()


async def _get(client: Client, name: str, command: str) -> np.ndarray:
    final = await (await client.create_process(name, command, check=False)).result()
    assert final.state is C, final.reason
    return np.asarray(from_data(final.data), dtype=float).reshape(-1)


@pytest.mark.slow
@pytest.mark.parametrize("vendor", VENDORS, ids=lambda v: v.name)
def test_a_program_on_the_pc_moves_the_twin(vendor, library, tmp_path, monkeypatch):
    monkeypatch.setenv("PLUGCELL_HOME", str(tmp_path / "home"))
    port = free_port("udp")

    async def scenario() -> None:
        twin = vendor.robot(port)
        try:
            service = _service(vendor, port, library, unique_cell(), tmp_path)
            await _start(service, twin)
            try:
                async with Client("STREAMTEST", cell=service.cell) as client:
                    assert await client.wait_for(service.name, 20)
                    home = await _get(client, service.name, "ARM_JNTP")
                    np.testing.assert_allclose(home, [0, -90, -187, 0, 90, 0], atol=0.01)

                    final = await _run(client, service.name, "rsimoves")
                    assert final.state is C, final.reason
                    motion = service.interface.bridge.motion  # type: ignore[attr-defined]
                    assert service.interface.bridge.drive.followed == 3  # type: ignore[attr-defined]
                    end = np.degrees(motion.last.sample(motion.last.duration, 0).q)
                    await asyncio.sleep(0.5)  # the servo settles
                    joints = await _get(client, service.name, "ARM_JNTP")
                    # at the LIN's end within the twin's following error at rest
                    np.testing.assert_allclose(joints, end.reshape(-1), atol=0.05)
                    status = await _get_status(client, service.name)
                    assert status[1] == "FINISHED" and "done" in status[4:]

                    # refused before motion: the line, the move and why; the robot stays
                    for program, why in (("unreachable", "POS_TO_JNTP"),
                                         ("beyond", "outside the joint limits")):
                        final = await _run(client, service.name, program)
                        assert final.state is F
                        assert f"{program}.pdl:4:" in final.reason, final.reason
                        assert "MOVE TO" in final.reason and why in final.reason, final.reason
                    before = await _get(client, service.name, "ARM_JNTP")
                    np.testing.assert_allclose(before, [2, -88, -186, 0, 88, 2], atol=0.05)
            finally:
                await service.close()
        finally:
            twin.kill()

    asyncio.run(asyncio.wait_for(scenario(), 180))


async def _start(service: RobotService, twin) -> None:
    """The service, then the robot once the service's link listens (a controller's
    timeout counts from its first packet)."""
    await start_with_controller(service, twin)


async def _get_status(client: Client, name: str) -> list[str]:
    final = await (await client.create_process(name, "PROGRAM_STATUS", check=False)).result()
    assert final.state is C, final.reason
    return [str(s) for s in from_data(final.data).reshape(-1)]


async def _state(service: GenericDevice, state: ConnectionStates, within: float) -> bool:
    end = time.monotonic() + within
    while service.device.connection is not state and time.monotonic() < end:
        await asyncio.sleep(0.05)
    return service.device.connection is state


@pytest.mark.slow
@pytest.mark.parametrize("vendor", VENDORS, ids=lambda v: v.name)
def test_a_stopped_stream_fails_the_process_and_the_service_recovers(vendor, library,
                                                                     tmp_path, monkeypatch):
    monkeypatch.setenv("PLUGCELL_HOME", str(tmp_path / "home"))
    port = free_port("udp")
    twin = vendor.robot(port)

    async def scenario() -> None:
        service = _service(vendor, port, library, unique_cell(), tmp_path)
        await _start(service, twin)
        try:
            async with Client("STREAMTEST", cell=service.cell) as client:
                assert await client.wait_for(service.name, 20)
                call = await client.create_process(service.name, "ACTIVATE", "Wait",
                                                   ["swing"], timeout=120)
                await asyncio.sleep(1.5)  # swinging
                twin.kill()
                t_kill = time.monotonic()
                final = await call.result()
                took = time.monotonic() - t_kill
                assert final.state is F
                assert f"{vendor.name} stream stopped" in final.reason, final.reason
                # within one controller timeout (plus the service's own bookkeeping)
                assert took < TIMEOUT_S + 3.0, took
                assert await _state(service, ConnectionStates.Error, 2.0)
                refused = await (await client.create_process(service.name, "ARM_JNTP",
                                                             check=False)).result()
                assert refused.state is F
                assert f"{vendor.name} stream stopped" in refused.reason, refused.reason

                twin.start()  # the robot comes back: a new session
                assert await _state(service, ConnectionStates.Online, 20.0)
                final = await _run(client, service.name, "rsimoves")
                assert final.state is C, final.reason
        finally:
            await service.close()
            twin.kill()

    asyncio.run(asyncio.wait_for(scenario(), 180))


def test_bad_rsi_options_are_refused_with_the_reason():
    with pytest.raises(ValueError, match=r"give one of sim, line=HOST:PORT, rsi"):
        RobotService(sim=True, rsi="127.0.0.1:49152")
    with pytest.raises(ValueError, match="rsi_robot names the controller of an RSI stream"):
        RobotService(sim=True, rsi_robot="10.0.0.1")
    with pytest.raises(ValueError, match="listens on every address: give the controller's"):
        RobotService(rsi="0.0.0.0:49152")
    with pytest.raises(ValueError, match="bad controller address"):
        RobotService(rsi="localhost")
    with pytest.raises(ValueError, match="bad RSI robot address"):
        RobotService(rsi="0.0.0.0:49152", rsi_robot="10.0.0.1:http")
    with pytest.raises(ValueError, match="joint_speed must be a positive number"):
        RobotService(rsi="127.0.0.1:49152", joint_speed=0.0)
    with pytest.raises(ValueError, match="timeout_packets"):
        RobotService(rsi="127.0.0.1:49152", rsi_timeout=0)
    with pytest.raises(ValueError, match="unknown robot 'scara4'"):
        RobotService(rsi="127.0.0.1:49152", robot="scara4")


def test_bad_egm_options_are_refused_with_the_reason():
    with pytest.raises(ValueError, match=r"give one of sim, line=HOST:PORT, rsi=HOST:PORT "
                       r"or egm=HOST:PORT, not several"):
        RobotService(rsi="127.0.0.1:49152", egm="127.0.0.1:6510")
    with pytest.raises(ValueError, match="egm_robot names the controller of an EGM stream"):
        RobotService(sim=True, egm_robot="10.0.0.1")
    with pytest.raises(ValueError, match=r"egm=0\.0\.0\.0:… listens on every address: give the "
                       r"controller's address with egm_robot"):
        RobotService(egm="0.0.0.0:6510")
    with pytest.raises(ValueError, match="bad EGM robot address"):
        RobotService(egm="0.0.0.0:6510", egm_robot="10.0.0.1:http")
    with pytest.raises(ValueError, match="comm_timeout_s"):
        RobotService(egm="127.0.0.1:6510", egm_timeout=0.001)
    with pytest.raises(ValueError, match="tcp_speed must be a positive number"):
        RobotService(egm="127.0.0.1:6510", tcp_speed=-1.0)
    service = GenericDevice(RobotService(egm="127.0.0.1:6510", egm_robot="127.0.0.2"), "R1",
                            journal=False)
    # the UI's device panel shows the link
    assert "ABB EGM, listening on 127.0.0.1:6510 for the controller at 127.0.0.2" in \
        service.device.info


def test_a_calibration_is_the_tracked_moves_model_and_a_bad_one_is_refused(tmp_path):
    """``--param calibration=PARAMS.json``: the streamed robot's tracked moves predict with
    it (tests/robot/test_tracked_moves.py measures what it changes); a file that cannot be
    read, is no calibration or is of another robot stops the service with the reason."""
    from calibrated import calibrated

    from plugcell.devices.robot.tracked_moves import TrackedMoves

    result, params = calibrated(tmp_path)
    service = RobotService(rsi="127.0.0.1:49152", calibration=str(params))
    link = service.bridge
    assert link.calibration is not None and link.calibration_name == "params.json"
    q = np.radians([[10.0, -30.0, -90.0, 20.0, 40.0, -10.0]])
    np.testing.assert_allclose(link.calibration.model.predict(q, np.array([36.0])),
                               result.model.predict(q, np.array([36.0])), atol=1e-9)
    moves = TrackedMoves(link.motion, lambda name: None, calibration=link.calibration,
                         calibration_name=link.calibration_name)
    assert moves.model_text == "the calibrated model (params.json, 36 kg)"
    assert RobotService(rsi="127.0.0.1:49152").bridge.calibration is None
    missing = tmp_path / "none.json"
    with pytest.raises(ValueError, match=rf"calibration {missing}: cannot read: No such file"):
        RobotService(rsi="127.0.0.1:49152", calibration=str(missing))
    garbled = tmp_path / "garbled.json"
    garbled.write_text("{not json")
    with pytest.raises(ValueError, match=rf"calibration {garbled}: not a plugcell "
                       "calibration: JSONDecodeError"):
        RobotService(rsi="127.0.0.1:49152", calibration=str(garbled))
    with pytest.raises(ValueError, match=r"the calibration is of the robot 'smart_h4', this "
                       r"robot is 'fanuc_m20ia'"):
        RobotService(rsi="127.0.0.1:49152", robot="fanuc_m20ia", calibration=str(params))
