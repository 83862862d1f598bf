"""Helpers of the metrology-service tests: cells, child processes, the simulated world."""

from __future__ import annotations

import asyncio
import uuid
from collections.abc import AsyncIterable, Coroutine
from typing import Any

import numpy as np
from childproc import Proc, plugcell_argv  # noqa: F401  (re-exported for the tests)

from plugcell.framework import ProcessCall
from plugcell.io.units import pose_from_robot


def unique_cell(prefix: str = "m") -> str:
    """A fresh cell name: tests never see each other (nor anything else on the host)."""
    return f"{prefix}{uuid.uuid4().hex[:12]}"


def run(coro: Coroutine[Any, Any, Any], timeout: float = 45.0) -> Any:
    """Run an async test body with a hard timeout."""
    return asyncio.run(asyncio.wait_for(coro, timeout))


def pose(v: list[float]) -> np.ndarray:
    """A 6-vector (mm, deg, Euler ZYZ) as a 4×4 matrix in metres."""
    return pose_from_robot(v, "zyz")




async def take_rows(updates: AsyncIterable[Any], count: int,
                    rows: list[np.ndarray] | None = None) -> list[np.ndarray]:
    """The data rows of a stream's ``updates`` appended to ``rows`` until it holds
    ``count`` (the updates without data passed over); ``rows``."""
    rows = [] if rows is None else rows
    async for update in updates:
        if update.data is not None:
            rows.append(ProcessCall.array(update))
            if len(rows) >= count:
                break
    return rows
