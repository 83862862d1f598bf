"""The seam between the compute service and what computes: :class:`ComputeEngine`.

The service (:mod:`plugcell.devices.compute.service`) does the thesis's part of Table
7-2 — the workspace of each requester, Set and Get Matrix, routing — and hands an
Evaluate's text to an engine, which runs it in the requester's workspace: in the thesis
Matlab, here :class:`FunctionEngine`, the expression language of
:mod:`~plugcell.devices.compute.expr` over the registered functions of
:mod:`~plugcell.devices.compute.functions`, in a worker thread (``plugcell serve
compute``) or a worker process of its own (``--param worker=process``), so that the
service keeps answering while it computes.  Another engine (a numerical package behind
the same names) is another class with :meth:`ComputeEngine.evaluate` and
:meth:`~ComputeEngine.close`, given to the service by ``plugcell serve compute``
(``apps/kinds.py``).
"""

from __future__ import annotations

import asyncio
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Protocol, runtime_checkable

from plugcell.devices.compute.expr import EvaluationError, evaluate
from plugcell.devices.compute.functions import FUNCTIONS, FunctionContext
from plugcell.devices.compute.workspace import Workspace, WorkspaceError

__all__ = ["WORKERS", "ComputeEngine", "Evaluation", "FunctionEngine"]


@dataclass(frozen=True)
class Evaluation:
    """What an Evaluate did: the names it assigned, in order, and the warnings of its
    functions (the service notes them on the process: the reason of its Completed
    update)."""

    names: list[str]
    warnings: list[str]


@runtime_checkable
class ComputeEngine(Protocol):
    """What runs an Evaluate (module docstring)."""

    async def evaluate(self, text: str, workspace: Workspace, params_dir: Path
                       ) -> Evaluation:
        """Run the expression ``text`` in ``workspace`` (its results stored there).

        Parameters
        ----------
        text : str
            One or more statements ``name = function(args…)`` (docs/compute-service.md).
        workspace : Workspace
            The requester's workspace: the values the expression reads, and where its
            results go.
        params_dir : Path
            Where the requester's parameter sets are saved and loaded.

        Returns
        -------
        Evaluation
            The names assigned and the warnings.

        Raises
        ------
        EvaluationError, WorkspaceError
            The expression is refused (the message names the place and the reason), or
            a result does not fit the workspace; what was assigned before stays.
        """
        ...

    async def close(self) -> None:
        """Release what the engine holds (a worker process, a licence); the service
        calls it when it stops."""
        ...


#: Where :class:`FunctionEngine` runs an Evaluate.
WORKERS = ("thread", "process")


class FunctionEngine:
    """The registered functions, evaluated by a worker (module docstring).

    Parameters
    ----------
    robot : str
        The robot the functions calibrate and compensate by default (a shipped name or a
        description file).
    worker : {"thread", "process"}
        ``thread`` (default): in a worker thread of the service's process, on the
        requester's workspace itself.  ``process``: in a process of its own (started at
        the first Evaluate, started again if it dies), on a copy of the workspace that
        comes back with the results — what was assigned and cleared, also by an
        expression that fails halfway.  The service's process then never computes, so it
        answers while a calibration runs without sharing its interpreter, and a function
        that crashes ends the worker, not the service; the copy costs a pickling of the
        workspace each way.

    Raises
    ------
    ValueError
        An unknown worker.
    """

    params: ClassVar[dict[str, type]] = {"robot": str, "worker": str}

    def __init__(self, robot: str = "smart_h4", worker: str = "thread") -> None:
        if worker not in WORKERS:
            raise ValueError(f"worker must be one of {', '.join(WORKERS)}, not {worker!r}")
        self.robot = robot
        self.worker = worker
        self._pool: ProcessPoolExecutor | None = None

    async def evaluate(self, text: str, workspace: Workspace, params_dir: Path
                       ) -> Evaluation:
        if self.worker == "thread":
            return await asyncio.to_thread(_evaluate, self.robot, text, workspace, params_dir)
        if self._pool is None:
            self._pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"))
        try:
            done, values, error = await asyncio.get_running_loop().run_in_executor(
                self._pool, _evaluate_copy, self.robot, text, workspace.owner,
                workspace.max_elements, workspace.snapshot(), params_dir)
        except BrokenProcessPool:
            self._pool = None
            raise EvaluationError(f"the compute engine's worker process ended while it "
                                  f"evaluated {text!r}; the workspace is as it was") from None
        workspace.restore(values)
        if error is not None:
            raise error
        return done

    async def close(self) -> None:
        """End the worker process, if one was started."""
        pool, self._pool = self._pool, None
        if pool is not None:
            await asyncio.to_thread(pool.shutdown, True, cancel_futures=True)


def _evaluate(robot: str, text: str, workspace: Workspace, params_dir: Path) -> Evaluation:
    """Evaluate ``text`` in ``workspace`` with the registered functions."""
    context = FunctionContext(workspace=workspace, robot=robot, params_dir=params_dir)
    names = evaluate(text, workspace, FUNCTIONS, context=context)
    return Evaluation(names, context.warnings)


def _evaluate_copy(robot: str, text: str, owner: str, max_elements: int,
                   values: dict[str, Any], params_dir: Path
                   ) -> tuple[Evaluation | None, dict[str, Any], Exception | None]:
    """In the worker process: :func:`_evaluate` on a workspace of ``values``; what it did,
    the workspace's values afterwards, and the refusal (None: it went through)."""
    workspace = Workspace(owner, max_elements)
    workspace.restore(values)
    try:
        return _evaluate(robot, text, workspace, params_dir), workspace.snapshot(), None
    except (EvaluationError, WorkspaceError) as exc:
        return None, workspace.snapshot(), exc
