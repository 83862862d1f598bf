"""docs/new-device.md: its service is complete, under 100 lines, and works as documented."""

from __future__ import annotations

import asyncio
import importlib.util
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
from framework_testlib import plugcell_argv, run, unique_cell

from plugcell.framework import Client, GenericDevice, ProcessStates

pytestmark = pytest.mark.timeout(90)

DOC = Path(__file__).resolve().parents[2] / "docs" / "new-device.md"


def doc_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), re.S)


@pytest.fixture
def laser_module(tmp_path, monkeypatch):
    code = doc_blocks()[0]
    path = tmp_path / "laser_point.py"
    path.write_text(code, encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    spec = importlib.util.spec_from_file_location("laser_point", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules["laser_point"] = module
    spec.loader.exec_module(module)
    yield module
    sys.modules.pop("laser_point", None)


def test_the_documented_service_is_under_100_lines():
    assert len(doc_blocks()[0].strip().splitlines()) < 100


def test_the_documented_device_is_composed_not_derived(laser_module):
    from plugcell.framework.participant import Participant

    assert not issubclass(laser_module.LaserPointService, Participant)


def test_the_documented_service_works(laser_module, tmp_path):
    async def body():
        cell = unique_cell()
        laser = GenericDevice(laser_module.LaserPointService(), cell=cell,
                              journal=tmp_path / "j")
        await laser.start()
        try:
            async with Client("ROBOT", cell=cell) as robot:
                assert await robot.wait_for("LASER")
                measure = await (await robot.create_process("LASER", "Measure")).result()
                assert measure.state is ProcessStates.Completed
                assert 249.0 < robot_value(measure) < 251.0
                zero = await (await robot.create_process("LASER", "Zero")).result()
                assert zero.state is ProcessStates.Completed
                track = await robot.create_process("LASER", "Track", data=500)
                values = []
                async for update in track:
                    if update.data is None:
                        continue
                    values.append(robot_value(update))
                    if len(values) == 3:
                        stop = await (await robot.stop_process(track)).result()
                        assert stop.state is ProcessStates.Completed
                assert track.final.state is ProcessStates.Completed
                assert all(abs(v) < 1.0 for v in values)  # zeroed
                bad = await (await robot.create_process("LASER", "Track", data=5000)).result()
                assert bad.reason == "Track: rate 5000 Hz outside 1…1000 Hz"
        finally:
            await laser.close()

    run(body())


def robot_value(update) -> float:
    from plugcell.framework import from_data

    return float(from_data(update.data)[0])


def test_the_documented_test_snippet_runs(laser_module):
    snippet = doc_blocks()[-1].replace('"test-laser"', repr(unique_cell()))
    namespace = {"LaserPointService": laser_module.LaserPointService, "asyncio": asyncio}
    exec(compile(snippet, str(DOC), "exec"), namespace)


def test_serve_module_class_from_the_cli(laser_module, procs, cell, tmp_path):
    env = {"PYTHONPATH": str(tmp_path)}
    procs.serve("laser_point:LaserPointService", cell, env=env)
    result = subprocess.run(
        plugcell_argv("call", "LASER", "Measure", "--cell", cell),
        capture_output=True,
        text=True,
        timeout=60,
        env={**procs.env, **env},
    )
    assert result.returncode == 0, result.stderr
    last = json.loads(result.stdout.splitlines()[-1])
    assert last["state"] == "Completed" and last["data"]["type"] == "Double"
