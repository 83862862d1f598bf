"""Checking a task before it is assigned (thesis 7.6, Figure 7-10).

"The operator firstly selects a service ... All the commands provided by the
selected service ... will be displayed ... from which the operator provides
necessary optional parameters and input data before activating them."  A task is
one command of one service with its Option string and its input data; the data
must fit the command's declared type and n-D size (appendix F.5).

:func:`check_task` turns what a form, the CLI or a file says into a command and a
typed buffer, or raises :class:`TaskInputError` with one message *per field*
(``service``, ``command``, ``option``, ``data``, ``timeout``) so a form can show
each error beside its field.  It never raises anything else, whatever the input.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from plugcell.framework.data import DataError, describe, to_data
from plugcell.framework.keys import check_name
from plugcell.framework.messages import Command, Data, DataTypes, Device

#: Longest Option string a task may carry.
MAX_OPTION = 1024
#: Most elements of input data typed into a form (larger data comes from files).
MAX_ELEMENTS = 1_000_000
#: Deepest nesting of input data (the rank limit of F.5 plus one for strings).
MAX_DEPTH = 9
MAX_TIMEOUT = 7 * 86400.0

__all__ = ["CheckedTask", "TaskInputError", "check_task", "describe_command"]


class TaskInputError(ValueError):
    """A task that cannot be assigned: ``errors`` maps each bad field to why."""

    def __init__(self, errors: dict[str, str]) -> None:
        super().__init__("; ".join(f"{k}: {v}" for k, v in errors.items()))
        self.errors = errors


@dataclass(frozen=True)
class CheckedTask:
    """A task that fits its command's declaration."""

    service: str
    command: Command
    option: str
    data: Data | None
    timeout: float


def describe_command(command: Command) -> dict[str, Any]:
    """A command of a catalogue as JSON, with its declarations in words (for forms)."""
    return {
        "name": command.name,
        "type": command.type.value,
        "input": {
            "type": command.input_data_type.value if command.input_data_type else None,
            "size": list(command.input_data_size),
            "text": describe(command.input_data_type, command.input_data_size),
        },
        "output": {
            "type": command.output_data_type.value if command.output_data_type else None,
            "size": list(command.output_data_size),
            "text": describe(command.output_data_type, command.output_data_size),
        },
        "successCode": command.success_code,
        "timeout": command.timeout,
        "info": command.info,
    }


def _depth_and_count(value: Any, depth: int = 0) -> tuple[int, int]:
    """Nesting depth and element count of nested lists, stopping early when too big."""
    if not isinstance(value, list | tuple):
        return depth, 1
    if depth >= MAX_DEPTH:
        return depth + 1, 0
    deepest, count = depth + 1, 0
    for item in value:
        d, c = _depth_and_count(item, depth + 1)
        deepest, count = max(deepest, d), count + c
        if deepest > MAX_DEPTH or count > MAX_ELEMENTS:
            break
    return deepest, count


def _non_finite(value: Any) -> bool:
    if isinstance(value, float):
        return not math.isfinite(value)
    if isinstance(value, list | tuple):
        return any(_non_finite(v) for v in value)
    return False


def _check_data(command: Command, data: Any) -> Data | None:
    depth, count = _depth_and_count(data)
    if depth > MAX_DEPTH:
        raise DataError(f"nested more than {MAX_DEPTH} levels deep")
    if count > MAX_ELEMENTS:
        raise DataError(f"more than {MAX_ELEMENTS} values")
    if isinstance(data, dict):
        raise DataError("expected a value or an array, got an object")
    if command.input_data_type is DataTypes.Double and _non_finite(data):
        raise DataError("values must be finite numbers")
    if isinstance(data, str) and command.input_data_type not in (DataTypes.String, None):
        raise DataError(f"{describe(command.input_data_type, command.input_data_size)} "
                        f"expected, got text")
    try:
        return to_data(data, command.input_data_type, command.input_data_size, "input")
    except DataError:
        raise
    except (ValueError, TypeError, OverflowError, RecursionError) as exc:
        raise DataError(f"cannot read the input: {exc}") from None


def check_task(
    device: Device | None,
    service: Any,
    command: Any,
    option: Any = "",
    data: Any = None,
    timeout: Any = None,
) -> CheckedTask:
    """Check a task against ``device``'s catalogue (``device`` None: service unknown)."""
    errors: dict[str, str] = {}
    if not isinstance(service, str) or not service:
        errors["service"] = "choose a service"
    else:
        try:
            check_name(service, "service name")
        except ValueError as exc:
            errors["service"] = str(exc)
    if "service" not in errors and device is None:
        errors["service"] = f"no service {service!r} in the cell"
    if option is None:
        option = ""
    if not isinstance(option, str):
        errors["option"] = "the option is a text"
    elif len(option) > MAX_OPTION:
        errors["option"] = f"longer than {MAX_OPTION} characters"
    elif any(ord(c) < 32 and c != "\t" for c in option):
        errors["option"] = "control characters are not allowed"
    seconds = 0.0
    if timeout is not None and timeout != "":
        if isinstance(timeout, bool) or not isinstance(timeout, int | float):
            errors["timeout"] = "the timeout is a number of seconds"
        elif not (math.isfinite(timeout) and 0 < timeout <= MAX_TIMEOUT):
            errors["timeout"] = f"between 0 and {MAX_TIMEOUT:g} s"
        else:
            seconds = float(timeout)
    cmd: Command | None = None
    if not isinstance(command, str) or not command:
        errors["command"] = "choose a command"
    elif device is not None:
        cmd = device.command(command)
        if cmd is None:
            known = ", ".join(c.name for c in device.commands) or "none"
            errors["command"] = f"{device.name} has no command {command!r} (commands: {known})"
    typed: Data | None = None
    if cmd is not None:
        try:
            typed = _check_data(cmd, data)
        except DataError as exc:
            text = str(exc)
            errors["data"] = text[len("input: "):] if text.startswith("input: ") else text
    if errors:
        raise TaskInputError(errors)
    assert cmd is not None and isinstance(service, str) and isinstance(option, str)
    return CheckedTask(service, cmd, option, typed, seconds or cmd.timeout)
