"""`serve --sim --robot --seed`: device flags reach the kinds that have them."""

from __future__ import annotations

import argparse

import pytest

from plugcell.apps.cli import CommandError, main
from plugcell.apps.commands.serve import _device_options, _params


def _args(**kw):
    base = dict(sim=False, controller=None, robot=None, payload_kg=None, speed=None, seed=None)
    base.update(kw)
    return argparse.Namespace(**base)


def test_robot_flags_become_parameters():
    kind = "robot"
    pairs = _device_options(kind, _args(sim=True, robot="elbow6", payload_kg=36.0, speed=50.0,
                                       seed=3))
    kw = _params(kind, pairs)
    assert kw == {"sim": True, "robot": "elbow6", "payload_kg": 36.0, "speed": 50.0, "seed": 3}


def test_tracker_sim_selects_the_model_driver():
    kind = "tracker"
    assert _params(kind, _device_options(kind, _args(sim=True, seed=4))) == {
        "driver": "sim", "seed": 4}


def test_flags_a_kind_does_not_have_are_refused(capsys):
    with pytest.raises(CommandError, match="--robot: not an option of TrackerService"):
        _device_options("tracker", _args(robot="smart_h4"))
    assert main(["serve", "camera", "--sim", "--cell", "flags-test"]) == 2
    assert "has no simulated mode" in capsys.readouterr().err


def test_a_serial_line_rate_that_is_not_a_rate_is_refused():
    from plugcell.apps.commands.sim_controller import main as controller_main
    from plugcell.devices.robot.service import RobotService

    with pytest.raises(ValueError, match=r"link_baud must be 0 \(no serial line\) or positive"):
        RobotService(sim=True, link_baud=-1.0)
    assert controller_main(["--link-baud", "-5", "--no-world"]) == 2


def test_opcua_device_flags_become_parameters():
    kind = "opcua-device"
    pairs = _device_options(kind, _args(endpoint="opc.tcp://127.0.0.1:4840", map="gripper.toml"))
    assert _params(kind, pairs) == {"endpoint": "opc.tcp://127.0.0.1:4840", "map": "gripper.toml"}
    pairs = _device_options(kind, _args(endpoint="opc.tcp://plc:4840", map="g.toml", trust="pki",
                                        insecure_accept_any=True))
    assert _params(kind, pairs) == {"endpoint": "opc.tcp://plc:4840", "map": "g.toml",
                                    "trust": "pki", "insecure_accept_any": True}
    with pytest.raises(CommandError, match="--insecure-accept-any: not an option of Camera"):
        _device_options("camera", _args(insecure_accept_any=True))


def test_a_urdf_robot_reaches_the_robot_service_as_a_description_file(tmp_path, monkeypatch):
    """`serve robot --robot ur.urdf.xacro --robot-arg …`: the robot service and its simulated
    controller take a robot as one string, so the import is written once as a description
    file under $PLUGCELL_HOME/robots and its path is passed on (reused when unchanged)."""
    from shared_data import UR_XACRO, URDF_DIR

    from plugcell.io.robots import load_robot

    if not UR_XACRO.is_file():
        pytest.skip(f"the shared URDF data are not at {URDF_DIR}")
    monkeypatch.setenv("PLUGCELL_HOME", str(tmp_path))
    kind = "robot"
    args = _args(sim=True, robot=str(UR_XACRO), robot_arg=["ur_type=ur10", "name=ur10"],
                 package_path=[str(URDF_DIR)], base_link=None, tip_link=None)
    kw = _params(kind, _device_options(kind, args))
    path = kw["robot"]
    assert path.startswith(str(tmp_path / "robots" / "ur10-")) and path.endswith(".toml")
    imported = load_robot(UR_XACRO, args={"ur_type": "ur10", "name": "ur10"},
                          package_paths=[URDF_DIR])
    again = load_robot(path)
    assert again.name == "ur10"
    q = imported.home + 0.3
    from plugcell.kinematics import forward

    a = forward(imported, imported.nominal_parameters(), q).flange
    b = forward(again, again.nominal_parameters(), q).flange
    assert abs(a - b).max() < 1e-12
    assert _params(kind, _device_options(kind, args))["robot"] == path  # the same file
    assert len(list((tmp_path / "robots").iterdir())) == 1


def test_urdf_options_without_a_robot_are_refused():
    with pytest.raises(CommandError, match="give it with --robot FILE"):
        _device_options("robot", _args(robot_arg=["ur_type=ur10"]))


def test_a_kind_with_a_driver_interface_is_served_with_its_simulated_driver():
    """``plugcell serve drill``: the device never imports the simulator; the kinds registry
    builds the simulated driver from the parameters it declares and hands it over."""
    from plugcell.apps.kinds import build, kind_params
    from plugcell.devices.drill import DrillDriver, DrillService
    from plugcell.sim.drivers.drill import SimulatedDrill

    assert kind_params("drill") == {"time_scale": float, "depth_mm": float}
    params = _params("drill", ["depth_mm=5", "time_scale=0"])
    service = build("drill", "T", params, cell="kinds-test", journal=False)
    assert isinstance(service.interface, DrillService) and service.name == "T"
    drill = service.interface.drill
    assert isinstance(drill, SimulatedDrill) and isinstance(drill, DrillDriver)
    assert (drill.depth_mm, drill.time_scale) == (5.0, 0.0)
    with pytest.raises(CommandError, match=r"bad --param 'depth_mm=1' for CameraService "
                                           r"\(parameters: time_scale\)"):
        _params("camera", ["depth_mm=1"])


def test_rsi_flags_become_robot_parameters():
    kind = "robot"
    pairs = _device_options(kind, _args(rsi="192.168.1.100:49152", rsi_robot="192.168.1.147",
                                        rsi_timeout=100, robot="smart_h4"))
    assert _params(kind, pairs) == {"rsi": "192.168.1.100:49152", "rsi_robot": "192.168.1.147",
                                    "rsi_timeout": 100, "robot": "smart_h4"}
    with pytest.raises(CommandError, match="--rsi: not an option of TrackerService"):
        _device_options("tracker", _args(rsi="127.0.0.1:49152"))


def test_egm_flags_become_robot_parameters():
    kind = "robot"
    pairs = _device_options(kind, _args(egm="192.168.125.100:6510", egm_robot="192.168.125.1",
                                        egm_timeout=2.5, robot="smart_h4"))
    assert _params(kind, pairs) == {"egm": "192.168.125.100:6510",
                                    "egm_robot": "192.168.125.1", "egm_timeout": 2.5,
                                    "robot": "smart_h4"}
    with pytest.raises(CommandError, match="--egm: not an option of TrackerService"):
        _device_options("tracker", _args(egm="127.0.0.1:6510"))
