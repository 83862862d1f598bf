"""Checking tasks against the command catalogues (thesis 7.6, Figure 7-10; appendix F.5)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.devices.camera import CameraService
from plugcell.devices.cell.tasks import TaskInputError, check_task, describe_command
from plugcell.devices.compute.service import ComputeService
from plugcell.devices.drill import DrillService
from plugcell.devices.tracker.service import TrackerService
from plugcell.framework.data import from_data, size_matches
from plugcell.framework.messages import Device

DEVICES = {
    d.name(): Device(name=d.name(), commands=d.commands)
    for d in (cls.declaration for cls in (CameraService, DrillService, TrackerService,
                                          ComputeService))
}
TOOL, CAMERA, TRACKER, COMPUTE = (DEVICES[n] for n in ("TOOL", "CAMERA", "TRACKER", "COMPUTE"))


def test_a_good_task_becomes_a_typed_buffer() -> None:
    task = check_task(TOOL, "TOOL", "Drill", "Air", [550, 1100])
    assert task.command.name == "Drill" and task.option == "Air" and task.timeout == 120.0
    assert from_data(task.data).tolist() == [550, 1100]
    task = check_task(TRACKER, "TRACKER", "Set Base", "rpy2tr", [1, 2, 3, 0, 0, 0.5], 3)
    assert task.timeout == 3.0 and task.data.type.value == "Double"
    task = check_task(COMPUTE, "COMPUTE", "Set Matrix", "mT", [[1, 2], [3, 4]])
    assert from_data(task.data).shape == (2, 2)
    assert check_task(CAMERA, "CAMERA", "Connect").data is None


@pytest.mark.parametrize(
    ("args", "field", "text"),
    [
        ((None, "GHOST", "Drill"), "service", "no service 'GHOST'"),
        ((TOOL, "bad/name", "Drill"), "service", "invalid service name"),
        ((TOOL, "TOOL", "Mill"), "command", "TOOL has no command 'Mill' (commands: Drill)"),
        ((TOOL, "TOOL", ""), "command", "choose a command"),
        ((TOOL, "TOOL", "Drill", "Air", [550]), "data", "size [1] does not match the declared [2]"),
        ((TOOL, "TOOL", "Drill", "Air", [550.5, 1100]), "data", "Integer expected"),
        ((TOOL, "TOOL", "Drill", "Air", None), "data", "Integer[2] expected, got no data"),
        ((TOOL, "TOOL", "Drill", "Air", "550,1100"), "data", "got text"),
        ((TOOL, "TOOL", "Drill", 7, [1, 2]), "option", "text"),
        ((TOOL, "TOOL", "Drill", "a\nb", [1, 2]), "option", "control characters"),
        ((TOOL, "TOOL", "Drill", "Air", [1, 2], -1), "timeout", "between 0"),
        ((TOOL, "TOOL", "Drill", "Air", [1, 2], "x"), "timeout", "number of seconds"),
        ((TRACKER, "TRACKER", "Move", "", [1, 2, 3, 4, 5, math.nan]), "data", "finite"),
        ((CAMERA, "CAMERA", "Connect", "", 5), "data", "no data expected"),
        ((COMPUTE, "COMPUTE", "Evaluate", "", {"x": 1}), "data", "got an object"),
    ],
)
def test_each_bad_field_gets_its_own_message(args: tuple, field: str, text: str) -> None:
    with pytest.raises(TaskInputError) as err:
        check_task(*args)
    assert field in err.value.errors
    assert text in err.value.errors[field]


def test_several_bad_fields_are_reported_together() -> None:
    with pytest.raises(TaskInputError) as err:
        check_task(TOOL, "TOOL", "Drill", "x" * 2000, [1], 0)
    assert set(err.value.errors) == {"option", "data", "timeout"}


def test_describe_command_names_the_declarations() -> None:
    d = describe_command(CAMERA.command("SnapShot"))
    assert d["input"] == {"type": "Integer", "size": [1], "text": "Integer[1]"}
    assert d["output"]["text"] == "Byte[480, 640]" and d["type"] == "SingleData"


JSON = st.recursive(
    st.none() | st.booleans() | st.integers(-2**40, 2**40) | st.floats() | st.text(max_size=6),
    lambda inner: st.lists(inner, max_size=7)
    | st.dictionaries(st.text(max_size=4), inner, max_size=3),
    max_leaves=40,
)
COMMANDS = [(d, c.name) for d in DEVICES.values() for c in d.commands]


@settings(max_examples=600, deadline=None)
@given(target=st.sampled_from(COMMANDS), data=JSON, option=JSON, timeout=JSON)
def test_any_input_is_a_task_or_field_errors(target: tuple, data: object, option: object,
                                             timeout: object) -> None:
    device, command = target
    try:
        task = check_task(device, device.name, command, option, data, timeout)
    except TaskInputError as exc:
        assert exc.errors and set(exc.errors) <= {"option", "data", "timeout"}
        assert all(isinstance(v, str) and v for v in exc.errors.values())
        return
    declared = device.command(command)
    if declared.takes_input:
        assert task.data is not None and task.data.type is declared.input_data_type
        assert size_matches(task.data.size, declared.input_data_size)
        arr = from_data(task.data)
        if arr.dtype.kind == "f":
            assert np.all(np.isfinite(arr))
    else:
        assert task.data is None
