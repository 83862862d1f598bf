"""``[identification]`` of a robot description file: which robot it is (the OPC UA
gateway's DI/OPC 40010 identification; docs/robot-description.md)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.io.robots import load_robot, robot_identification, robot_path
from plugcell.kinematics.errors import DescriptionError


def test_the_shipped_robots_say_who_made_them():
    assert robot_identification("smart_h4") == {
        "manufacturer": "Comau", "model": "Smart H4", "serial_number": "", "product_code": ""}
    assert robot_identification("fanuc_m20ia")["manufacturer"] == "FANUC"
    assert set(robot_identification("elbow6").values()) == {""}  # a virtual robot: none


def _with(tmp_path, table: str):
    text = robot_path("elbow6").read_text()
    path = tmp_path / "robot.toml"
    path.write_text(text.replace("[[links]]", table + "\n[[links]]", 1))
    return path


def test_a_nameplate_in_a_copy_of_a_file_is_read_and_the_robot_still_loads(tmp_path):
    path = _with(tmp_path, '[identification]\nmanufacturer = "ACME"\nserial_number = "SN-42"\n')
    assert robot_identification(path) == {"manufacturer": "ACME", "model": "",
                                          "serial_number": "SN-42", "product_code": ""}
    assert load_robot(path).name == "elbow6"


def test_a_bad_table_is_refused_naming_the_key(tmp_path):
    with pytest.raises(DescriptionError, match=r"robot.toml: identification.colour: unknown key"):
        robot_identification(_with(tmp_path, '[identification]\ncolour = "orange"\n'))
    with pytest.raises(DescriptionError, match=r"robot.toml: identification.serial_number: "
                       r"expected a string, got 42"):
        load_robot(_with(tmp_path, "[identification]\nserial_number = 42\n"))


@settings(max_examples=30, deadline=None)
@given(st.dictionaries(st.sampled_from(["manufacturer", "model", "serial_number",
                                         "product_code"]),
                       st.text(alphabet=st.characters(blacklist_categories=("Cs", "Cc")),
                               max_size=20)))
def test_any_text_round_trips(tmp_path_factory, values):
    import json

    table = "[identification]\n" + "".join(
        f"{k} = {json.dumps(v, ensure_ascii=False)}\n" for k, v in values.items())
    path = _with(tmp_path_factory.mktemp("ident"), table)
    got = robot_identification(path)
    assert got == {k: values.get(k, "") for k in got}
