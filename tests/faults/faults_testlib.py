"""Helpers of the fault-injection tests: a cell of service processes."""

from __future__ import annotations

from childproc import CellProcesses

#: A cell whose services run as OS processes (all stopped after the test).
FaultCell = CellProcesses
