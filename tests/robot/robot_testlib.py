"""Helpers of the robot tests: child processes, unique cells, bounded polling."""

from __future__ import annotations

import uuid

from childproc import (  # noqa: F401  (re-exported for the robot tests)
    Proc,
    group_alive,
    plugcell_argv,
    until,
)
from controller_start import start_with_controller  # noqa: F401  (re-exported)


def unique_cell(prefix: str = "r") -> str:
    """A fresh cell name: tests never see each other (nor anything else on the host)."""
    return f"{prefix}{uuid.uuid4().hex[:12]}"

