"""The seam between the compute service and what computes: :class:`ComputeEngine`.

The service (:mod:`plugcell.devices.compute.service`) does the thesis's part of Table
7-2 — the workspace of each requester, Set and Get Matrix, routing — and hands an
Evaluate's text to an engine, which runs it in the requester's workspace: in the thesis
Matlab, here by default :class:`FunctionEngine`, the expression language of
:mod:`~plugcell.devices.compute.expr` over the registered functions of
:mod:`~plugcell.devices.compute.functions`, in a worker thread so that the service keeps
answering while it computes.  Another engine (a process of its own, a numerical
package behind the same names) is another class with :meth:`ComputeEngine.evaluate`,
given to the service by ``plugcell serve compute`` (``apps/kinds.py``).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Protocol, runtime_checkable

from plugcell.devices.compute.expr import evaluate
from plugcell.devices.compute.functions import FUNCTIONS, FunctionContext
from plugcell.devices.compute.workspace import Workspace

__all__ = ["ComputeEngine", "Evaluation", "FunctionEngine"]


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


class FunctionEngine:
    """The registered functions, evaluated in a worker thread (module docstring).

    Parameters
    ----------
    robot : str
        The robot the functions calibrate and compensate by default (a shipped name or a
        description file).
    functions : mapping of str to callable, optional
        The functions an expression may call (default: every registered one).
    """

    params: ClassVar[dict[str, type]] = {"robot": str}

    def __init__(self, robot: str = "smart_h4",
                 functions: Mapping[str, Callable[..., Any]] | None = None) -> None:
        self.robot = robot
        self.functions = FUNCTIONS if functions is None else functions

    async def evaluate(self, text: str, workspace: Workspace, params_dir: Path
                       ) -> Evaluation:
        return await asyncio.to_thread(self.run, text, workspace, params_dir)

    def run(self, text: str, workspace: Workspace, params_dir: Path) -> Evaluation:
        """:meth:`evaluate`, in the calling thread."""
        context = FunctionContext(workspace=workspace, robot=self.robot, params_dir=params_dir)
        names = evaluate(text, workspace, self.functions, context=context)
        return Evaluation(names, context.warnings)
