"""The compute service: the Matlab service of thesis 7.3 (Table 7-2), without Matlab.

==============  ===========================  =====================  ==================  ==========
command         option                       input                  output              type
==============  ===========================  =====================  ==================  ==========
Set Matrix      matrix_name [":append"]      matrix: Double[m, n]   —                   NoData
Get Matrix      matrix_name                  —                      matrix: Double[m,n] SingleData
Evaluate        —                            expression: String[1]  —                   NoData
==============  ===========================  =====================  ==================  ==========

* **A workspace per requester** (``compute/workspace.py``): each robot's ``mT`` is its
  own.  The requester is the process's sender, or the participant a routed process is
  for (``for=``, set by the service that routed the data — ``tracker/routing.py``).
* **Set Matrix** stores ``matrix`` as ``matrix_name``; with ``:append`` its rows are
  appended (the matrix is created if absent) — how the calibration program adds each
  measurement to mT and each joint reading to mJ (8.2.2).  A vector is one row.
* **Evaluate** runs an expression of the small language of ``compute/expr.py`` —
  assignments of calls to **registered** functions only (``compute/functions.py``:
  calibrate, validate, summary, load/save parameters, frame, compensate,
  compensate_joints, calc_targets, …).  No arbitrary code is ever executed: anything
  else is refused with the reason, and the service carries on.
* A function's **warnings** (``compensate`` and ``compensate_joints``: targets outside
  the region the parameters were calibrated on, with how far — docs/planning.md) come
  back as the reason of the Evaluate process's ``Completed`` update (a robot program
  reads it as ``ext_cmd_message``) and in the service's log.
* **Get Matrix** returns a matrix (identified parameters are not matrices: use
  ``frame(params, 'base')`` etc.).  Its output can be routed (``; to=…``) like any
  other, e.g. straight into the tracker's Set Base.

An Evaluate runs in the service's engine (:class:`~plugcell.devices.compute.engine.ComputeEngine`;
``plugcell serve compute`` gives it :class:`~plugcell.devices.compute.engine.FunctionEngine`,
``--param robot=…``): heavy functions in a worker thread (``--param worker=process``: a
worker process), one process at a time (the queue), so the service keeps answering Get and
notifications while it computes.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from plugcell.devices.compute.engine import ComputeEngine
from plugcell.devices.compute.expr import EvaluationError
from plugcell.devices.compute.workspace import DEFAULT_MAX_ELEMENTS, Workspace, WorkspaceError
from plugcell.devices.tracker.routing import Routing
from plugcell.framework.declaration import Declaration
from plugcell.framework.journal import plugcell_home
from plugcell.framework.messages import Command, CommandTypes, DataTypes
from plugcell.framework.service import DeviceError, GenericDevice

log = logging.getLogger("plugcell.devices.compute.service")

APPEND = ":append"

__all__ = ["ComputeService"]


class ComputeService:
    """Set Matrix, Get Matrix, Evaluate on per-requester workspaces (module docstring);
    the device a :class:`~plugcell.framework.service.GenericDevice` hosts."""

    declaration = Declaration(
        kind="compute",
        default_name="COMPUTE",
        vendor="plugcell",
        info="Computing service (thesis Table 7-2): workspaces per robot, registered functions",
        commands=(
        Command(
            name="Set Matrix", type=CommandTypes.NoData,
            input_data_type=DataTypes.Double, input_data_size=(),
            info="store the data as OPTION (a name; 'name:append' appends the rows); "
                 "a vector is one row",
        ),
        Command(
            name="Get Matrix", type=CommandTypes.SingleData,
            output_data_type=DataTypes.Double, output_data_size=(-1, -1),
            info="the matrix named OPTION ('name@OWNER': read another requester's) "
                 "[; to=SERVICE:Command:Option]",
        ),
        Command(
            name="Evaluate", type=CommandTypes.NoData,
            input_data_type=DataTypes.String, input_data_size=(1,), timeout=600.0,
            info="run 'name = function(args…)'; registered functions only (docs/"
                 "compute-service.md)",
        ),
    ))
    params: ClassVar[dict[str, type]] = {"data_dir": str, "max_elements": int}

    def __init__(
        self,
        driver: ComputeEngine,
        *,
        data_dir: str | Path | None = None,
        max_elements: int = DEFAULT_MAX_ELEMENTS,
    ) -> None:
        """``driver``: the engine that runs Evaluate (``plugcell serve compute``: the
        registered functions, :class:`~plugcell.devices.compute.engine.FunctionEngine`);
        ``data_dir``: where parameter sets are saved (:attr:`data_dir`);
        ``max_elements``: the most matrix elements a workspace holds."""
        if max_elements < 1:
            raise ValueError(f"max_elements must be positive, got {max_elements}")
        self.engine = driver
        self._data_dir = Path(data_dir) if data_dir is not None else None
        self.max_elements = max_elements
        self.workspaces: dict[str, Workspace] = {}
        """The workspace of each requester, by name."""
        self.routing = Routing(self.handle)
        """Who each process is for, and where its output goes (tracker/routing.py)."""
        self.service: GenericDevice | None = None

    def bind(self, service: GenericDevice) -> None:
        self.service = service
        self.routing.bind(service)

    async def disconnect(self) -> None:
        """The service stops: so does its engine."""
        await self.engine.close()

    async def dispatch(self, command: Command, option: str, data: Any) -> str | None:
        """Through the routing: the requester, then :meth:`handle`, then the routes."""
        return await self.routing.dispatch(command, option, data)

    @property
    def data_dir(self) -> Path:
        """Where parameter sets are saved: ``<home>/cells/<cell>/compute/<name>``."""
        if self._data_dir is not None:
            return self._data_dir
        assert self.service is not None
        return plugcell_home() / "cells" / self.service.cell / "compute" / self.service.name

    def workspace(self, requester: str) -> Workspace:
        """The workspace of ``requester`` (created empty on first use)."""
        ws = self.workspaces.get(requester)
        if ws is None:
            ws = self.workspaces[requester] = Workspace(requester, self.max_elements)
        return ws

    async def handle(self, command: Command, option: str, data: Any) -> str:
        """CommandDispatcher of Table 7-2, in the workspace of the process's requester."""
        service = self.service
        assert service is not None
        ws = self.workspace(self.routing.requester)
        try:
            match command.name:
                case "Set Matrix":
                    name, append = _target(option)
                    if append:
                        ws.append(name, data)
                    else:
                        ws.set(name, np.asarray(data, dtype=float))
                case "Get Matrix":
                    self.routing.data_feedback.post(self._readable(ws, option.strip()))
                case "Evaluate":
                    text = str(np.asarray(data, dtype=object).reshape(-1)[0])
                    done = await self.engine.evaluate(text, ws, self.data_dir / "params")
                    log.info("%s: %s evaluated %r → %s", service.name, ws.owner, text,
                             done.names)
                    for w in done.warnings:
                        log.warning("%s: %s: %s", service.name, ws.owner, w)
                        service.note(w)
                case _:
                    raise DeviceError(f"unknown command {command.name}")
        except (WorkspaceError, EvaluationError) as exc:
            raise DeviceError(str(exc)) from None
        return "OK"

    def _readable(self, ws: Workspace, ref: str) -> np.ndarray:
        """``name`` in the requester's workspace, or ``name@OWNER`` in OWNER's — read
        only, so that a cell controller or an engineer can look at what a robot's
        program measured (the workspaces keep robots from mixing data, not secrets)."""
        name, at, owner = ref.partition("@")
        if not at:
            return ws.matrix(name)
        owner = owner.strip()
        other = self.workspaces.get(owner)
        if other is None:
            known = ", ".join(sorted(self.workspaces)) or "none"
            raise WorkspaceError(f"no workspace of {owner!r} (workspaces: {known})")
        return other.matrix(name.strip())


def _target(option: str) -> tuple[str, bool]:
    text = option.strip()
    if text.endswith(APPEND):
        return text[: -len(APPEND)].strip(), True
    return text, False
