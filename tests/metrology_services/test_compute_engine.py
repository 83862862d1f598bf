"""The compute service's engine behind its interface (issue 33): the registered functions
in a worker thread (``plugcell serve compute``) and in a worker process of their own
(``--param worker=process``) do the same to a requester's workspace — the names assigned,
the warnings, what an expression that fails halfway leaves — and the service runs with
either."""

from __future__ import annotations

import asyncio
import os
import signal
import uuid
from pathlib import Path

import numpy as np
import pytest
from test_compute_functions import campaign, rows  # noqa: F401  (campaign: a fixture)

from plugcell.apps.kinds import build
from plugcell.devices.compute.engine import ComputeEngine, Evaluation, FunctionEngine
from plugcell.devices.compute.expr import EvaluationError
from plugcell.devices.compute.workspace import Workspace, WorkspaceError
from plugcell.framework import Client, ProcessCall, ProcessStates

C, F = ProcessStates.Completed, ProcessStates.Failed


def test_an_engine_has_the_interface_and_serve_gives_the_thread_worker():
    assert isinstance(FunctionEngine(), ComputeEngine)
    with pytest.raises(ValueError, match="worker must be one of thread, process, not 'gpu'"):
        FunctionEngine(worker="gpu")
    service = build("compute", None, {"robot": "smart_h4", "max_elements": 100},
                    journal=False)
    engine = service.interface.engine
    assert isinstance(engine, FunctionEngine) and (engine.robot, engine.worker) == (
        "smart_h4", "thread")
    assert service.interface.max_elements == 100
    process = build("compute", None, {"worker": "process"}, journal=False).interface.engine
    assert process.worker == "process"


async def _both(cases: list[tuple[str, dict]], tmp_path: Path
                ) -> list[list[tuple[Evaluation | Exception, dict]]]:
    """Each ``(text, values)`` evaluated by each worker (one engine each) on a workspace
    of ``values``: per case, what each worker gave (or raised) and the workspace after."""
    out: list[list[tuple[Evaluation | Exception, dict]]] = [[] for _ in cases]
    for worker in ("thread", "process"):
        engine = FunctionEngine(worker=worker)
        try:
            for k, (text, values) in enumerate(cases):
                ws = Workspace("ROBOT", max_elements=10_000)
                ws.restore(values)
                try:
                    done: Evaluation | Exception = await engine.evaluate(text, ws,
                                                                         tmp_path / worker)
                except (EvaluationError, WorkspaceError) as exc:
                    done = exc
                out[k].append((done, ws.snapshot()))
        finally:
            await engine.close()
    return out


def _same(a: dict, b: dict) -> None:
    assert sorted(a) == sorted(b)
    for name in a:
        np.testing.assert_array_equal(a[name], b[name])


@pytest.mark.slow
def test_both_workers_leave_the_same_workspace(tmp_path):
    """Results, clear(), a failure halfway (what was assigned before it stays), a result
    too big for the workspace — the same either way."""
    values = {"mT": np.arange(6.0).reshape(2, 3), "old": np.zeros((1, 1))}

    cases = asyncio.run(_both([
        ("n = size(mT); clear('old')", values),
        ("a = size(mT); b = nosuch(a)", values),
        ("a = append(mT, mT); b = append(a, a)", {"mT": np.zeros((1, 2500))}),
    ], tmp_path))
    (done, after), (pdone, pafter) = cases[0]
    assert done == pdone == Evaluation(["n"], [])
    _same(after, pafter)
    assert sorted(after) == ["mT", "n"]
    (err, after), (perr, pafter) = cases[1]
    assert isinstance(err, EvaluationError) and type(perr) is type(err)
    assert str(perr) == str(err) and "unknown function 'nosuch'" in str(err)
    _same(after, pafter)
    assert "a" in after and "b" not in after
    (err, after), (perr, pafter) = cases[2]
    assert str(perr) == str(err) and "limit of 10000" in str(err)
    _same(after, pafter)
    assert sorted(after) == ["a", "mT"]


@pytest.mark.slow
def test_both_workers_calibrate_alike_and_warn_alike(campaign, tmp_path):  # noqa: F811
    """A calibration (Parameters, not a matrix, in the workspace), its frame, and the
    compensation of a target far outside the calibrated region: the same names, values
    and warning from either worker."""
    cal, _ = campaign
    mJ, mT = rows(cal)
    # a pose well inside the calibrated joint ranges, its first joint then moved beyond
    # them (as test_compute_service.py does)
    k = np.argsort(np.abs((mJ - np.median(mJ, axis=0)) / np.ptp(mJ, axis=0)).max(1))[:1]
    far = mJ[k].copy()
    far[0, 0] = mJ[:, 0].max() + 25.0
    values = {"mJ": mJ, "mT": mT, "far": far}
    text = ("params = calibrate(mJ, mT, model=4, payload=36); base = frame(params, 'base'); "
            "q = compensate_joints(params, far, 36)")
    [[(done, after), (pdone, pafter)]] = asyncio.run(_both([(text, values)], tmp_path))
    assert isinstance(done, Evaluation), done
    assert done == pdone
    assert done.names == ["params", "base", "q"]
    assert len(done.warnings) == 1
    assert "1 of 1 targets outside the calibrated region" in done.warnings[0]
    np.testing.assert_allclose(pafter["base"], after["base"], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(pafter["q"], after["q"], rtol=1e-12, atol=1e-12)
    assert pafter["params"].kind == after["params"].kind == "identified parameters"


@pytest.mark.slow
def test_the_service_runs_with_a_worker_process(tmp_path, monkeypatch):
    monkeypatch.setenv("PLUGCELL_HOME", str(tmp_path / "home"))

    async def body() -> None:
        cell = f"ceng{uuid.uuid4().hex[:8]}"
        service = build("compute", None, {"worker": "process"}, cell=cell, journal=False)
        await service.start()
        try:
            async with Client("ROBOT", cell=cell) as robot:
                assert await robot.wait_for("COMPUTE", 10)

                async def final(command: str, option: str = "", data=None):
                    return await (await robot.create_process("COMPUTE", command, option, data,
                                                             timeout=60)).result()

                assert (await final("Set Matrix", "mT", np.ones((4, 3)))).state is C
                assert (await final("Evaluate", "", "n = size(mT)")).state is C
                got = await final("Get Matrix", "n")
                np.testing.assert_array_equal(ProcessCall.array(got), [[4, 3]])
                bad = await final("Evaluate", "", "x = nosuch(mT)")
                assert bad.state is F and "unknown function 'nosuch'" in bad.reason
                # the worker dies: that Evaluate fails, the workspace is as it was, the
                # next one gets a new worker
                pool = service.interface.engine._pool
                for pid in list(pool._processes):
                    os.kill(pid, signal.SIGKILL)
                await asyncio.sleep(0.5)
                lost = await final("Evaluate", "", "n = size(mT)")
                assert lost.state is F and "worker process ended" in lost.reason, lost.reason
                assert (await final("Evaluate", "", "m = size(mT)")).state is C
                got = await final("Get Matrix", "m")
                np.testing.assert_array_equal(ProcessCall.array(got), [[4, 3]])
            pool = service.interface.engine._pool
            assert pool is not None
        finally:
            await service.close()
        assert service.interface.engine._pool is None  # the worker ended with the service

    asyncio.run(asyncio.wait_for(body(), 90))
