"""A tracked move end to end (issue 38): the robot service over KUKA RSI runs a program's
``MOVE LINEAR TO p WITH TRACKING`` with the tracker service's ``Stream Measurement`` in
the loop — the twin's RSI side in its own process (``plugcell twin rsi --reflector ROBOT
--cell C``: publishing its moving T-MAC on the simulated world), the tracker service and
the robot service in this one, its link in a thread (``stream_process=false``: the
correction is computed beside the link; with the link in its child process a tracked move
fails with that reason, tests/robot/test_tracked_moves.py).

The program sets the tracker's BASE and PROBE (the cell's, here the twin's true ones),
aims the beam with Move, then runs the tracked line: the service opens the stream itself,
its loop takes the samples, and the program ends FINISHED; the tracker is free again.
"""

from __future__ import annotations

import asyncio
import shutil
from pathlib import Path

import numpy as np
import pytest
from robot_testlib import unique_cell
from test_service_streamed import TIMEOUT, _get_status, _run, _start

import plugcell.pdl
from plugcell.apps.kinds import build
from plugcell.devices.robot.live_tracking import decode_tracking
from plugcell.devices.robot.service import RobotService
from plugcell.framework import Client, ProcessStates
from plugcell.io.units import robot_from_pose
from plugcell.sim.controller.rsi_twin import RsiTwinProcess
from plugcell.sim.ports import free_port
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario

PROGRAM = """\
PROGRAM tracked
IMPORT 'services'
VAR p : POSITION
    text : STRING[255]
BEGIN
  IF NOT EXT_CMD('TRACKER', 'Set Base', 'euler2tr', '{base}', 60000) THEN
    WRITE LUN_CRT ('Set Base: ', ext_cmd_message)
    DEACTIVATE
  ENDIF
  IF NOT EXT_CMD('TRACKER', 'Set Probe', 'euler2tr', '{probe}', 60000) THEN
    WRITE LUN_CRT ('Set Probe: ', ext_cmd_message)
    DEACTIVATE
  ENDIF
  ENCODE (text, ARM_POS)
  IF NOT EXT_CMD('TRACKER', 'Move', 'euler2tr', text, 60000) THEN
    WRITE LUN_CRT ('Move: ', ext_cmd_message)
    DEACTIVATE
  ENDIF
  p := ARM_POS
  p.Y := p.Y + 60
  MOVE LINEAR TO p WITH TRACKING
  WRITE LUN_CRT ('tracked')
END tracked
"""


async def _live_move_heard(heard: list[bytes], name: str, stats) -> None:
    """The service published the move as it went (devices/robot/live_tracking.py): its
    identity, batches in order whose points cover its cycles, and its end."""
    for _ in range(100):
        if heard and decode_tracking(heard[-1]).end is not None:
            break
        await asyncio.sleep(0.1)
    batches = [decode_tracking(b) for b in heard]
    assert batches and batches[-1].end is not None, batches[-1:]
    assert {b.service for b in batches} == {name}
    assert {(b.identity.program, b.identity.run, b.identity.move, b.identity.tracker)
            for b in batches} == {("tracked", batches[0].identity.run, "tracked.1", "TRACKER")}
    seqs = [b.seq for b in batches]
    assert seqs == sorted(seqs) and len(batches) >= 3, seqs  # as it went, not at the end
    points = [p for b in batches for p in b.points]
    assert 0 < len(points) <= stats.cycles and points[-1].t_s > 0
    assert batches[-1].end.cycles == stats.cycles
    assert any(p.measured_m is not None for p in points)


def _vector(T: np.ndarray) -> str:
    return ",".join(f"{v:.6f}" for v in robot_from_pose(T, "zyz"))


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_a_programs_tracked_move_streams_with_the_tracker(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setenv("PLUGCELL_HOME", str(tmp_path / "home"))
    twin = RobotTwin(TwinScenario(robot="smart_h4", seed=0))
    lib = tmp_path / "programs"
    lib.mkdir()
    shutil.copy(Path(plugcell.pdl.__file__).parent / "programs" / "services.pdl", lib)
    (lib / "tracked.pdl").write_text(PROGRAM.format(base=_vector(twin.true_base()),
                                                    probe=_vector(twin.reveal_truth().probe)))
    port, cell = free_port("udp"), unique_cell()

    async def scenario() -> None:
        tracker = build("tracker", None, {"seed": 5}, cell=cell, journal=False)
        await tracker.start()
        try:
            # lockstep: the twin waits for each answer as a real-time PC would give it,
            # so a loaded machine's late answers neither shake the arm nor add up to
            # its Timeout (this test is about the tracked move, not the PC's timing)
            robot = RsiTwinProcess(f"127.0.0.1:{port}", "--timeout", str(TIMEOUT),
                                   "--lockstep", "1", "--reflector", "ROBOT", "--cell", cell)
            try:
                service = build("robot", None, {"rsi": f"127.0.0.1:{port}",
                                                "rsi_timeout": TIMEOUT, "library": str(lib),
                                                "stream_process": False},
                                cell=cell, journal=tmp_path / "journal")
                assert isinstance(service.interface, RobotService)
                await _start(service, robot)
                try:
                    async with Client("RSITEST", cell=cell) as client:
                        heard: list[bytes] = []  # the move, live (as the controller hears it)
                        client.own(client.bus.watch_tracking(
                            lambda name, payload: heard.append(payload)))
                        assert await client.wait_for(service.name, 20)
                        assert await client.wait_for("TRACKER", 20)
                        wired = await client.ask_subscribe(service.name, "TRACKER")
                        assert wired.ok, wired.reason
                        final = await _run(client, service.name, "tracked", timeout=180)
                        status = await _get_status(client, service.name)
                        assert final.state is ProcessStates.Completed, (final.reason, status)
                        assert status[1] == "FINISHED" and "tracked" in status[4:], status
                        moves = service.interface.bridge.motion.move_tracked.__self__  # type: ignore
                        stats = moves.last_loop.stats
                        assert stats.samples_used > 200, stats
                        await _live_move_heard(heard, service.name, stats)
                        # the tracker is free again: another requester is served at once
                        other = await client.create_process("TRACKER", "Set Base", "euler2tr",
                                                            [0, 0, 0, 0, 0, 0], timeout=10)
                        assert (await other.result()).state is ProcessStates.Completed
                finally:
                    await service.close()
            finally:
                robot.kill()
        finally:
            await tracker.close()

    asyncio.run(asyncio.wait_for(scenario(), 220))
