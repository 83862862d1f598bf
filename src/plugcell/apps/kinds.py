"""The one registry of service kinds: ``plugcell serve KIND`` looks them up here.

A kind is a device (a :class:`~plugcell.framework.service.DeviceInterface`: its
declaration and ``dispatch``) and, for a device family with a driver interface
(the camera's :class:`~plugcell.devices.camera.CameraDriver`, the drill's
:class:`~plugcell.devices.drill.DrillDriver` …), the driver it runs with by default —
the simulated one of ``plugcell.sim`` for an instrument; for the OPC UA device the
asyncua client of its server, for the compute service its engine of registered
functions, each a real implementation in ``devices``.  The device never imports the simulator:
:func:`build` makes the driver, hands it to the device and the device to the
:class:`~plugcell.framework.service.GenericDevice` that hosts it (the kind's
parameters ``--param K=V`` go to whichever of the two declares them).

Add a kind with one line (``"laser": Kind("laser_point:LaserPointService")``) or, from
outside the package, with :func:`register_kind`.  Targets are imported only when
served, so a broken kind never breaks the others.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from plugcell.framework.declaration import Declaration
from plugcell.framework.service import GenericDevice

#: ``--param driver=sim``: the kind's default driver (a device declaring a ``driver``
#: parameter takes another by name, ``module:Class``).
SIMULATED = "sim"


@dataclass(frozen=True)
class Kind:
    """A service kind: its service class and its default driver, each ``"module:Class"``.

    Parameters
    ----------
    service : str
        The device class (a :class:`~plugcell.framework.service.DeviceInterface`: its
        ``declaration``, ``bind`` and ``dispatch``).
    driver : str or None
        The driver class the device is given as ``driver=`` (None: the device needs
        none).
    launcher : str or None
        What starts the device's own controller process, given (not called) as
        ``launcher=`` — the robot's simulated controller for ``sim=true``, which needs
        the service's name and cell.
    """

    service: str
    driver: str | None = None
    launcher: str | None = None


KINDS: dict[str, Kind] = {
    "camera": Kind("plugcell.devices.camera:CameraService",
                   driver="plugcell.sim.drivers.camera:SimulatedCamera"),
    "drill": Kind("plugcell.devices.drill:DrillService",
                  driver="plugcell.sim.drivers.drill:SimulatedDrill"),
    "bench": Kind("plugcell.apps.bench.device:BenchService"),
    "robot": Kind("plugcell.devices.robot.service:RobotService",
                  launcher="plugcell.sim.controller.launcher:SimControllerProcess"),
    "tracker": Kind("plugcell.devices.tracker.service:TrackerService",
                    driver="plugcell.sim.drivers.tracker:SimulatedTrackerDriver"),
    "compute": Kind("plugcell.devices.compute.service:ComputeService",
                    driver="plugcell.devices.compute.engine:FunctionEngine"),
    "cell-controller": Kind("plugcell.devices.cell.service:CellController"),
    "opcua-device": Kind("plugcell.devices.opcua.device:OpcUaDevice",
                         driver="plugcell.devices.opcua.client:AsyncuaDriver"),
}

#: Old kind names (issue #33) → the kind: ``plugcell serve controller`` still serves the
#: cell controller, with a deprecation warning (:func:`current_kind`).
DEPRECATED_KINDS: dict[str, str] = {"controller": "cell-controller"}
#: Old parameter names of a kind → the parameter: ``--param controller=HOST:PORT`` of
#: the robot is its line-protocol link, ``line`` (beside ``rsi``, ``egm``).
DEPRECATED_PARAMS: dict[str, dict[str, str]] = {"robot": {"controller": "line"}}


def current_kind(kind: str) -> str:
    """``kind``, or the kind an old name of :data:`DEPRECATED_KINDS` became (with the
    warning line of :func:`~plugcell.apps.commands.deprecated.warn_renamed`)."""
    from plugcell.apps.commands.deprecated import warn_renamed

    new = DEPRECATED_KINDS.get(kind)
    if new is None:
        return kind
    warn_renamed(f"service kind {kind!r}", repr(new))
    return new


def current_param(kind: str, key: str) -> str:
    """``key``, or the parameter of ``kind`` an old name of :data:`DEPRECATED_PARAMS`
    became (with a warning line)."""
    from plugcell.apps.commands.deprecated import warn_renamed

    new = DEPRECATED_PARAMS.get(kind, {}).get(key)
    if new is None:
        return key
    warn_renamed(f"parameter {key!r} of {kind}", repr(new))
    return new


def register_kind(kind: str, target: str | Kind) -> None:
    """Register ``kind`` → ``"module:Class"`` (a device class) or a :class:`Kind`."""
    KINDS[kind] = target if isinstance(target, Kind) else Kind(target)


def _kind(kind: str) -> Kind:
    found = KINDS.get(kind) or (Kind(kind) if ":" in kind else None)
    if found is None:
        known = ", ".join(sorted(KINDS))
        raise KeyError(f"unknown service kind {kind!r} (known: {known}, or module:Class)")
    return found


def _load(kind: str, target: str) -> Any:
    module_name, _, attr = target.partition(":")
    try:
        return getattr(importlib.import_module(module_name), attr)
    except (ImportError, AttributeError) as exc:
        raise KeyError(f"cannot load service kind {kind!r}: {exc}") from None


def load_kind(kind: str) -> type:
    """The device class of ``kind`` — a registered kind or ``"module:Class"``.

    KeyError (with the known kinds) if it cannot be found; TypeError if it is not a
    device class (a class with a :class:`~plugcell.framework.declaration.Declaration`).
    """
    target = _kind(kind).service
    cls = _load(kind, target)
    if not (isinstance(cls, type) and isinstance(getattr(cls, "declaration", None),
                                                  Declaration)):
        raise TypeError(f"{target} is not a device class (no Declaration 'declaration')")
    return cls


def load_driver(kind: str) -> type | None:
    """The default driver class of ``kind`` (None: its service takes no driver)."""
    target = _kind(kind).driver
    return None if target is None else _load(kind, target)


def kind_params(kind: str) -> dict[str, type]:
    """The parameters ``--param K=V`` of ``kind``: its device's and its driver's
    (each class's ``params``: name → the type that converts the text)."""
    driver = load_driver(kind)
    return {**getattr(load_kind(kind), "params", {}), **getattr(driver, "params", {})}


def build(kind: str, name: str | None, params: Mapping[str, Any], **options: Any
          ) -> GenericDevice:
    """A service of ``kind`` named ``name``: its device with its default driver, hosted.

    Parameters
    ----------
    kind : str
        A registered kind or ``"module:Class"``.
    name : str or None
        The service's name (None: the kind's default name).
    params : mapping of str to value
        The kind's parameters (:func:`kind_params`), already converted: those the
        driver declares build the driver, the others go to the device.
    **options
        The framework's keywords for the service (``cell``, ``transport``,
        ``journal``, ``max_payload`` …).

    Returns
    -------
    GenericDevice
        The service, not started.
    """
    cls = load_kind(kind)
    driver_cls = load_driver(kind)
    launcher = _kind(kind).launcher
    if launcher is not None:
        params = {**params, "launcher": _load(kind, launcher)}
    if driver_cls is None:
        return GenericDevice(cls(**params), name, **options)
    driver_keys = getattr(driver_cls, "params", {})
    device_params = {k: v for k, v in params.items() if k not in driver_keys}
    chosen = device_params.pop("driver", SIMULATED)
    if chosen != SIMULATED:  # ``--param driver=module:Class``: the device loads another
        return GenericDevice(cls(driver=chosen, **device_params), name, **options)
    driver = driver_cls(**{k: v for k, v in params.items() if k in driver_keys})
    return GenericDevice(cls(driver=driver, **device_params), name, **options)
