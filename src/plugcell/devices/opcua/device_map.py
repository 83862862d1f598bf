"""The device map of ``plugcell serve opcua-device``: which OPC UA nodes become commands.

A TOML file (docs/opcua.md, "OPC UA devices as services")::

    [device]
    name = "GRIPPER"                      # service name (``--name`` overrides)
    vendor = "ACME"
    info = "2-finger gripper, PLC over OPC UA"
    object = "nsu=urn:acme:gripper;s=Gripper"   # default object of the methods

    [[command]]                           # a method call
    name = "Close"
    type = "NoData"                       # NoData | SingleData | MultipleData | StopData
    method = "nsu=urn:acme:gripper;s=Gripper.Close"
    input = { type = "Double", size = [1] }     # passed as the method's argument
    info = "close with FORCE N"

    [[command]]                           # a variable read
    name = "Force"
    type = "SingleData"
    read = "nsu=urn:acme:gripper;s=Gripper.Force"
    output = { type = "Double", size = [1] }

    [[command]]                           # a variable streamed (an OPC UA subscription)
    name = "WatchForce"
    type = "MultipleData"
    subscribe = "nsu=urn:acme:gripper;s=Gripper.Force"
    output = { type = "Double", size = [1] }
    interval_ms = 50

    [[command]]
    name = "StopWatch"
    type = "StopData"

Every command has exactly one action matching its type: ``method`` (NoData,
SingleData: its first output argument is the data), ``write`` (NoData with input:
the input is written to the variable), ``read`` (SingleData), ``subscribe``
(MultipleData) or none (StopData, which ends the sender's subscription).  Node ids
are OPC UA's text form (``ns=2;s=…``, ``ns=2;i=5``) or, better since namespace
indexes can change, ``nsu=<namespace URI>;…``.  Optional per command: ``object``
(the method's object), ``arguments`` (``["option", "data"]``: what the method gets,
default the data if the command has input), ``timeout`` (s), ``success_code``,
``info``.  The parser only reads the file; whether the nodes exist is checked when
the service connects (:mod:`plugcell.devices.opcua.device`).
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec

from plugcell.framework.messages import Command, CommandTypes, DataTypes
from plugcell.framework.service import check_catalogue

#: The actions a command may name, and the command types each fits.
ACTIONS: dict[str, tuple[CommandTypes, ...]] = {
    "method": (CommandTypes.NoData, CommandTypes.SingleData),
    "write": (CommandTypes.NoData,),
    "read": (CommandTypes.SingleData,),
    "subscribe": (CommandTypes.MultipleData,),
}
_NODE_ID = re.compile(r"^(ns=\d+|nsu=[^;]+);[isgb]=.+$|^i=\d+$")
_COMMAND_KEYS = {"name", "type", "info", "timeout", "success_code", "input", "output", "object",
                 "arguments", "interval_ms", *ACTIONS}
_DEVICE_KEYS = {"name", "vendor", "info", "object"}


class DeviceMapError(ValueError):
    """A device map that cannot be used; the message names the file and the element."""


@dataclass(frozen=True)
class MappedCommand:
    """One catalogue command and the OPC UA node(s) it acts on."""

    command: Command
    action: str
    """``method``, ``write``, ``read``, ``subscribe`` or ``""`` (StopData)."""
    node: str
    """The node id text of the action's node (``""`` for StopData)."""
    object: str = ""
    """For ``method``: the object to call it on (``""``: the method's parent)."""
    arguments: tuple[str, ...] = ()
    """For ``method``: ``"option"``/``"data"`` in the order the method takes them."""
    interval_ms: float = 100.0
    """For ``subscribe``: the publishing interval asked of the server."""


@dataclass(frozen=True)
class DeviceMap:
    """A parsed device map (module docstring)."""

    name: str
    vendor: str
    info: str
    commands: tuple[MappedCommand, ...]
    source: str = "<memory>"

    def command(self, name: str) -> MappedCommand:
        return next(c for c in self.commands if c.command.name == name)


def load_device_map(path: str | Path) -> DeviceMap:
    """Read and check a device map file (DeviceMapError naming the file and the element)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise DeviceMapError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise DeviceMapError(f"{path}: not UTF-8 text: {exc}") from None
    return parse_device_map(text, str(path))


def parse_device_map(text: str, source: str = "<memory>") -> DeviceMap:
    """Parse the TOML text of a device map (see the module docstring)."""
    try:
        doc: dict[str, Any] = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise DeviceMapError(f"{source}: not TOML: {exc}") from None
    unknown = set(doc) - {"device", "command"}
    if unknown:
        raise DeviceMapError(f"{source}: unknown tables {sorted(unknown)} (device, command)")
    device = doc.get("device", {})
    if not isinstance(device, dict):
        raise DeviceMapError(f"{source}: [device] must be a table")
    _no_unknown(device, _DEVICE_KEYS, f"{source}: [device]")
    name = _text(device, "name", f"{source}: [device]", "OPCUA_DEVICE")
    default_object = _node(device, "object", f"{source}: [device]") if "object" in device else ""
    raw = doc.get("command", [])
    if not isinstance(raw, list) or not raw:
        raise DeviceMapError(f"{source}: no [[command]] (a device needs at least one)")
    commands = tuple(
        _command(entry, f"{source}: command {i + 1}", default_object)
        for i, entry in enumerate(raw)
    )
    try:
        check_catalogue(source, tuple(c.command for c in commands))
    except (ValueError, TypeError) as exc:
        raise DeviceMapError(str(exc)) from None
    return DeviceMap(
        name=name,
        vendor=_text(device, "vendor", f"{source}: [device]", ""),
        info=_text(device, "info", f"{source}: [device]", ""),
        commands=commands,
        source=source,
    )


def _no_unknown(table: dict[str, Any], known: set[str], where: str) -> None:
    unknown = set(table) - known
    if unknown:
        raise DeviceMapError(f"{where}: unknown keys {sorted(unknown)} (known: {sorted(known)})")


def _text(table: dict[str, Any], key: str, where: str, default: str) -> str:
    value = table.get(key, default)
    if not isinstance(value, str):
        raise DeviceMapError(f"{where}: {key} must be a string, got {type(value).__name__}")
    return value


def _node(table: dict[str, Any], key: str, where: str) -> str:
    value = _text(table, key, where, "")
    if not _NODE_ID.match(value):
        raise DeviceMapError(
            f"{where}: {key} = {value!r} is not an OPC UA node id (ns=N;s=… or nsu=URI;s=…)"
        )
    return value


def _data(table: dict[str, Any], key: str, where: str) -> tuple[DataTypes | None, tuple[int, ...]]:
    spec = table.get(key)
    if spec is None:
        return None, (0,)
    here = f"{where}: {key}"
    if not isinstance(spec, dict):
        raise DeviceMapError(f"{here} must be a table {{ type = …, size = […] }}")
    _no_unknown(spec, {"type", "size"}, here)
    type_name = spec.get("type")
    try:
        data_type = DataTypes(type_name)
    except ValueError:
        names = ", ".join(t.value for t in DataTypes)
        raise DeviceMapError(f"{here}: type {type_name!r} is not one of {names}") from None
    size = spec.get("size", [1])
    if (not isinstance(size, list) or not all(type(d) is int and d >= -1 for d in size)
            or len(size) > 8 or size == [0]):
        raise DeviceMapError(f"{here}: size {size!r} is not a list of dimensions ≥ -1 (F.5)")
    return data_type, tuple(size)


def _command(entry: Any, where: str, default_object: str) -> MappedCommand:
    if not isinstance(entry, dict):
        raise DeviceMapError(f"{where}: must be a table")
    _no_unknown(entry, _COMMAND_KEYS, where)
    name = _text(entry, "name", where, "")
    if not name:
        raise DeviceMapError(f"{where}: name is missing")
    where = f"{where} ({name!r})"
    type_name = entry.get("type")
    try:
        ctype = CommandTypes(type_name)
    except ValueError:
        names = ", ".join(t.value for t in CommandTypes)
        raise DeviceMapError(f"{where}: type {type_name!r} is not one of {names}") from None
    actions = [a for a in ACTIONS if a in entry]
    if len(actions) > 1:
        raise DeviceMapError(f"{where}: one action per command, got {actions}")
    action = actions[0] if actions else ""
    if ctype is CommandTypes.StopData:
        if action:
            raise DeviceMapError(f"{where}: a StopData command takes no {action} (it ends the "
                                 "sender's subscription)")
    elif not action:
        fits = [a for a, types in ACTIONS.items() if ctype in types]
        raise DeviceMapError(f"{where}: a {ctype.value} command needs one of {fits}")
    elif ctype not in ACTIONS[action]:
        raise DeviceMapError(f"{where}: {action} does not fit a {ctype.value} command")
    in_type, in_size = _data(entry, "input", where)
    out_type, out_size = _data(entry, "output", where)
    if action in ("read", "subscribe") and out_type is None:
        raise DeviceMapError(f"{where}: {action} needs output = {{ type = …, size = […] }}")
    if action == "write" and in_type is None:
        raise DeviceMapError(f"{where}: write needs input = {{ type = …, size = […] }}")
    if action in ("read", "subscribe", "") and in_type is not None:
        raise DeviceMapError(f"{where}: {action or 'StopData'} takes no input")
    if ctype in (CommandTypes.NoData, CommandTypes.StopData) and out_type is not None:
        raise DeviceMapError(f"{where}: a {ctype.value} command has no output")
    arguments = entry.get("arguments", ["data"] if in_type is not None else [])
    if (action != "method" and "arguments" in entry) or not isinstance(arguments, list) or any(
            a not in ("option", "data") for a in arguments) or len(set(arguments)) != len(
            arguments):
        raise DeviceMapError(f"{where}: arguments must be a list of 'option'/'data' (method "
                             f"commands only), got {arguments!r}")
    if "data" in arguments and in_type is None:
        raise DeviceMapError(f"{where}: arguments name 'data' but the command has no input")
    interval = entry.get("interval_ms", 100.0)
    if type(interval) not in (int, float) or not 1 <= interval <= 3_600_000:
        raise DeviceMapError(f"{where}: interval_ms must be a number of 1…3600000 ms")
    fields: dict[str, Any] = {
        "name": name, "type": ctype, "input_data_type": in_type, "input_data_size": in_size,
        "output_data_type": out_type, "output_data_size": out_size,
        "info": _text(entry, "info", where, ""),
        "success_code": _text(entry, "success_code", where, "OK"),
    }
    if "timeout" in entry:
        fields["timeout"] = entry["timeout"]
    try:  # built, then checked against the wire schema's constraints (timeout > 0 …)
        command = msgspec.convert(msgspec.to_builtins(Command(**fields)), Command)
    except (msgspec.ValidationError, TypeError) as exc:
        raise DeviceMapError(f"{where}: {exc}") from None
    return MappedCommand(
        command=command,
        action=action,
        node=_node(entry, action, where) if action else "",
        object=_node(entry, "object", where) if "object" in entry else (
            default_object if action == "method" else ""),
        arguments=tuple(arguments),
        interval_ms=float(interval),
    )
