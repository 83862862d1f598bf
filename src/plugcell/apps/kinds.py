"""The one registry of service kinds: ``plugcell serve KIND`` looks them up here.

Add a kind with one line (``"robot": "plugcell.devices.robot.service:RobotService"``) or,
from outside the package, with :func:`register_kind`.  Targets are imported only
when served, so a broken kind never breaks the others.
"""

from __future__ import annotations

import importlib

from plugcell.framework.service import GenericDevice

KINDS: dict[str, str] = {
    "camera": "plugcell.devices.camera:CameraService",
    "drill": "plugcell.devices.drill:DrillService",
    "bench": "plugcell.apps.bench.device:BenchService",
    "robot": "plugcell.devices.robot.service:RobotService",
    "tracker": "plugcell.devices.tracker.service:TrackerService",
    "compute": "plugcell.devices.compute.service:ComputeService",
    "controller": "plugcell.devices.cell.service:CellController",
    "opcua-device": "plugcell.devices.opcua.device:OpcUaDevice",
}


def register_kind(kind: str, target: str) -> None:
    """Register ``kind`` → ``"module:Class"`` (a GenericDevice subclass)."""
    KINDS[kind] = target


def load_kind(kind: str) -> type[GenericDevice]:
    """The service class of ``kind`` — a registered kind or ``"module:Class"``.

    KeyError (with the known kinds) if it cannot be found.
    """
    target = KINDS.get(kind, kind if ":" in kind else "")
    if not target:
        known = ", ".join(sorted(KINDS))
        raise KeyError(f"unknown service kind {kind!r} (known: {known}, or module:Class)")
    module_name, _, attr = target.partition(":")
    try:
        cls = getattr(importlib.import_module(module_name), attr)
    except (ImportError, AttributeError) as exc:
        raise KeyError(f"cannot load service kind {kind!r}: {exc}") from None
    if not (isinstance(cls, type) and issubclass(cls, GenericDevice)):
        raise TypeError(f"{target} is not a GenericDevice subclass")
    return cls
