"""The Data field of an ACTIVATE string against the partner's declaration (5.2.1.3, F.5)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.devices.camera import CameraService
from plugcell.devices.drill import DrillService
from plugcell.devices.robot.data import DataTextError, data_from_text, result_data
from plugcell.devices.robot.protocol import ResultData
from plugcell.devices.robot.service import RobotService
from plugcell.framework import Command, CommandTypes, DataTypes


def command(service: type, name: str) -> Command:
    return next(c for c in service.declaration.commands if c.name == name)


SNAP = command(CameraService, "SnapShot")
DRILL = command(DrillService, "Drill")
CONNECT = command(CameraService, "Connect")
MATRIX = Command(name="Set", type=CommandTypes.NoData, input_data_type=DataTypes.Double,
                 input_data_size=(2, 3))
FLAGS = Command(name="Flags", type=CommandTypes.NoData, input_data_type=DataTypes.Boolean,
                input_data_size=(-1,))
WORDS = Command(name="Words", type=CommandTypes.NoData, input_data_type=DataTypes.String,
                input_data_size=(-1,))


@pytest.mark.parametrize(
    ("cmd", "text", "expected"),
    [
        (SNAP, "500", [500]),
        (SNAP, ", 500", [500]),  # the form of 5.2.3.6
        (SNAP, " 500.000000 ", [500]),  # a PDL REAL holding a whole number
        (DRILL, "550,1100", [550, 1100]),
        (DRILL, "550 , 1100", [550, 1100]),
        (MATRIX, "1,2,3;4,5,6", [[1, 2, 3], [4, 5, 6]]),
        (MATRIX, "1,2,3,4,5,6", [[1, 2, 3], [4, 5, 6]]),  # flat, row-major
        (FLAGS, "TRUE,false,1,0", [True, False, True, False]),
        (WORDS, "a, b c,d", ["a", "b c", "d"]),
        (command(RobotService, "DEACTIVATE"), "my, program", ["my, program"]),
        (CONNECT, "", None),
    ],
)
def test_text_is_read_as_the_declared_input(cmd: Command, text: str, expected) -> None:
    value = data_from_text(text, cmd, "DEV")
    if expected is None:
        assert value is None
    else:
        assert np.asarray(value).tolist() == expected


@pytest.mark.parametrize(
    ("cmd", "text", "reason"),
    [
        (SNAP, "", "DEV SnapShot expects Integer[1], got no data"),
        (SNAP, "5.5", "DEV SnapShot: data '5.5' does not fit Integer[1]: value 1 '5.5' is not a "
                      "whole number (Integer)"),
        (SNAP, "1e10", "DEV SnapShot: data '1e10' does not fit Integer[1]: values outside the "
                       "Integer range"),
        (SNAP, "five", "DEV SnapShot: data 'five' does not fit Integer[1]: value 1 'five' is not "
                       "a number"),
        (DRILL, "550", "DEV Drill: data '550' does not fit Integer[2]: size [1] does not match "
                       "the declared [2]"),
        (DRILL, "550,,1100", "DEV Drill: data '550,,1100' does not fit Integer[2]: value 2 is "
                             "empty"),
        (MATRIX, "1,2;3", "DEV Set: data '1,2;3' does not fit Double[2, 3]: rows of different "
                          "lengths"),
        (MATRIX, "1,2,3,4", "DEV Set: data '1,2,3,4' does not fit Double[2, 3]: size [4] does "
                            "not match the declared [2, 3]"),
        (FLAGS, "TRUE,maybe", "DEV Flags: data 'TRUE,maybe' does not fit Boolean[*]: value 2 "
                              "'maybe' is not a Boolean"),
        (CONNECT, "now", "DEV Connect takes no data, got 'now'"),
    ],
)
def test_data_that_does_not_fit_is_refused_with_the_reason(cmd: Command, text: str,
                                                           reason: str) -> None:
    with pytest.raises(DataTextError) as info:
        data_from_text(text, cmd, "DEV")
    assert str(info.value).startswith(reason)


@settings(max_examples=1500)
@given(st.sampled_from([SNAP, DRILL, CONNECT, MATRIX, FLAGS, WORDS]), st.text(max_size=40))
def test_any_text_fits_or_is_refused(cmd: Command, text: str) -> None:
    try:
        data_from_text(text, cmd, "DEV")
    except DataTextError as exc:
        assert str(exc).startswith("DEV ")


def test_results_for_the_program_respect_its_capacity() -> None:
    assert result_data(None, 4096, 255) == (None, "")
    assert result_data(np.array([1.5, 2, 3]), 4096, 255) == (
        ResultData(3, 1, (1.5, 2.0, 3.0)), "")
    assert result_data(np.eye(4), 4096, 255)[0] == ResultData(4, 4, tuple(np.eye(4).ravel()))
    assert result_data(np.zeros((24, 4, 4)), 4096, 255)[0].cols == 16  # rows × the rest
    assert result_data(np.array([True, False]), 4096, 255)[0].values == (1.0, 0.0)
    image = np.zeros((480, 640), np.uint8)
    assert result_data(image, 4096, 255) == (
        None, "480×640 data (307200 values) does not fit ext_cmd_data (4096): "
              "not sent to the controller")
    words = np.array(["probe", "#7"], dtype=object)
    assert result_data(words, 4096, 255) == (ResultData(text="probe,#7"), "")
    assert result_data(np.array(["x" * 300], dtype=object), 4096, 255)[1].startswith(
        "text of 300 characters does not fit ext_cmd_text (255)")
    assert result_data(np.array([np.nan]), 4096, 255)[0] is None
    assert result_data(np.array([1.0]), 4096, 255, frame=True)[0].frame
