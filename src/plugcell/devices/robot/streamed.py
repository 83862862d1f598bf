"""The robot service's options of a robot streamed from the PC: which link, if any.

``rsi=HOST:PORT`` or ``egm=HOST:PORT`` make the service's link a
:class:`~.stream_controller.StreamController`: the programs run on the PC and each move
streams to the robot — issue 37's mode *the PC drives*, the controller's program only
starting the interface where the robot stands and following:

* a KUKA robot over RSI: absolute joint corrections (``AKorr``; the controller's files
  from ``plugcell rsi files --mode absolute``), joint feedback the packets' ``AIPos``;
* an ABB robot over EGM: joint targets (``EGMRunJoint``; ``plugcell egm files --mode
  joint``), joint feedback the ``EgmRobot`` messages' ``feedBack.joints``.

Without either, the service talks to a controller that runs the programs itself
(:class:`~.bridge.ControllerBridge`).  The link's limits follow the planner's
(:func:`~.stream_controller.streaming_limits`, policy *refuse*).

The same stream carries issue 37's mode (b), *the robot drives, the PC corrects*
(``CORRECT``, :mod:`.corrections`): the controller runs its own program and the service
superimposes corrections.  With the defaults above that is absolute joint corrections
(RSI) — and the PC's moves as well; ``rsi_correction=cartesian``, ``rsi_mode=relative``
or ``egm_mode=pathcorr`` (``EGMMoveL`` with path corrections) configure a stream for the
controller's own path only, the PC's moves then refused with the reason.  Such a stream's
limits are the vendor's correction limits (:func:`~.stream.limits.default_limits`).

The stream's modules (the controller, its tracked moves and their learning: SciPy's
signal processing, the calibration) are imported when a stream is asked for, not with
this module: a robot service whose controller runs the programs itself starts without
them (≈ 1.5 s of CPU less a process).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any

from plugcell.devices.params import flag
from plugcell.devices.robot.bridge import BridgeHandler, parse_address
from plugcell.devices.robot.egm.config import EgmConfig
from plugcell.devices.robot.rsi.config import RsiConfig
from plugcell.devices.robot.stream.realtime import stream_realtime
from plugcell.io.robots import load_robot

if TYPE_CHECKING:
    from plugcell.devices.robot.stream_controller import StreamController

__all__ = ["STREAM_PARAMS", "streamed_link"]

#: The robot service's options of a streamed robot (``--param KEY=VALUE``): name → parser.
STREAM_PARAMS: dict[str, Callable[[str], Any]] = {
    "rsi": str, "rsi_robot": str, "rsi_timeout": int, "rsi_correction": str, "rsi_mode": str,
    "rsi_frame": str, "egm": str, "egm_robot": str, "egm_timeout": float, "egm_mode": str,
    "stream_process": flag, "joint_speed": float, "tcp_speed": float,
    "correct_max_mm": float, "correct_max_deg": float, "calibration": str, "learned_dir": str,
    "learning_law": str, "stream_rt_priority": int, "stream_cpu": str, "stream_mlock": flag}


def _check_learning(learned_dir: str, learning_law: str) -> None:
    """Refuse an unknown learning law, or one without a folder to learn into."""
    if learning_law == "p":
        return
    from plugcell.io.learned_paths import LAWS  # module docstring: loaded when needed

    if learning_law not in LAWS:
        raise ValueError(f"learning_law must be one of {', '.join(LAWS)}, got {learning_law!r}")
    if learning_law != "p" and not learned_dir:
        raise ValueError(f"learning_law={learning_law} needs learned_dir=DIR: nothing is "
                         "learned without it")


def _check_streams(rsi: str, rsi_robot: str, egm: str, egm_robot: str) -> None:
    """Refuse both streams at once, or a controller's address without its stream."""
    if rsi and egm:
        raise ValueError("give rsi=HOST:PORT or egm=HOST:PORT, not both")
    for option, address, stream in (("rsi", rsi_robot, rsi), ("egm", egm_robot, egm)):
        if address and not stream:
            raise ValueError(f"{option}_robot names the controller of an {option.upper()} "
                             f"stream: give {option} too")


def _check_correction_limits(correct_max_mm: float, correct_max_deg: float) -> None:
    """Refuse a largest ``CORRECT`` correction that is not a positive finite number."""
    for what, v in (("correct_max_mm", correct_max_mm), ("correct_max_deg", correct_max_deg)):
        if not (v > 0 and v < float("inf")):
            raise ValueError(f"{what} must be a positive number, not {v}")


def _stream_controller() -> ModuleType:
    """:mod:`.stream_controller`, imported on first use (module docstring)."""
    import plugcell.devices.robot.stream_controller as module

    return module


def _endpoints(option: str, listen: str, address: str) -> dict[str, Any]:
    """The link's ``listen_host``/``listen_port`` and the controller's ``robot_host``/
    ``robot_port`` of the ``rsi``/``egm`` options ``listen`` and ``address``."""
    host, port = parse_address(listen)
    rhost, robot_port = _stream_controller().robot_endpoint(option, host, address)
    return {"robot_host": rhost, "listen_host": host, "listen_port": port,
            "robot_port": robot_port}


def streamed_link(handler: BridgeHandler, *, robot: str, library: Sequence[Path], name: str,
                  rsi: str = "", rsi_robot: str = "", rsi_timeout: int = 100,
                  rsi_correction: str = "joint", rsi_mode: str = "absolute",
                  rsi_frame: str = "base", egm: str = "", egm_robot: str = "",
                  egm_timeout: float = 1.0, egm_mode: str = "joint", joint_speed: float = 20.0,
                  tcp_speed: float = 100.0, stream_process: bool = True,
                  correct_max_mm: float = 5.0, correct_max_deg: float = 1.0,
                  calibration: str = "", stream_rt_priority: int | None = None,
                  stream_cpu: str = "", stream_mlock: bool = False, learned_dir: str = "",
                  learning_law: str = "p") -> StreamController | None:
    """The streamed robot's controller the options ask for, or ``None`` (none asked).

    Parameters
    ----------
    handler : BridgeHandler
        The robot service.
    robot : str
        The robot (a shipped name or a description file): its nominal model plans.
    library, name : sequence of Path, str
        Folders of robot programs; the service's name.
    rsi, rsi_robot, rsi_timeout, rsi_correction, rsi_mode, rsi_frame
        RSI: ``HOST:PORT`` where plugcell receives the controller's packets (the ethernet
        file's ``IP_NUMBER:PORT``), the controller's ``HOST[:PORT]`` (empty: the ``rsi``
        host unless a wildcard), the ETHERNET object's ``Timeout`` (cycles), ``joint`` or
        ``cartesian`` corrections, ``absolute`` or ``relative``, and the Cartesian
        corrections' frame, ``base`` or ``tool`` (POSCORR's ``RefCorrSys``; the
        controller's files).
    egm, egm_robot, egm_timeout, egm_mode
        EGM: ``HOST:PORT`` where plugcell receives ``EgmRobot`` (the UDP unit device's
        remote address), the controller's ``HOST[:PORT]``, ``EGMSetupUC``'s
        ``\\CommTimeout`` (s), ``joint`` (``EGMRunJoint``) or ``pathcorr`` (``EGMMoveL``).
    joint_speed, tcp_speed : float
        The planner's limits, °/s of every joint and mm/s of linear moves
        (:func:`~.stream_controller.planner_limits`).
    stream_process : bool
        The link's cycle loop in a child process (default) or a thread of the service's.
    correct_max_mm, correct_max_deg : float
        The largest correction ``CORRECT`` superimposes, per axis (mm; degrees of a
        rotation or a joint).
    calibration : str
        The tracked moves' model, the robot's PARAMS.json (empty: the nominal model).
    stream_rt_priority, stream_cpu, stream_mlock
        The cycle loop's scheduling (:class:`~.stream.realtime.RealTime`): its thread under
        ``SCHED_FIFO`` at this priority (1..99), the link's process (or thread) on these
        CPUs (``taskset -c`` syntax: ``1``, ``2-3``), its memory locked (``mlockall``).
    learned_dir, learning_law : str
        The tracked moves' learned corrections (:mod:`~.move_learning`; empty: none) and
        the law a new one starts with, ``p`` (the default) or ``inverse``.

    Returns
    -------
    StreamController or None
        Not yet connected.

    Raises
    ------
    ValueError
        Both streams, a controller address without its stream, a bad address, limit,
        timeout, robot, calibration, priority, CPU list or learning law: the reason.
    """
    _check_streams(rsi, rsi_robot, egm, egm_robot)
    _check_learning(learned_dir, learning_law)
    if not (rsi or egm):
        return None
    sc = _stream_controller()
    joint, cart = sc.planner_limits(joint_speed, tcp_speed)
    where = _endpoints(*(("rsi", rsi, rsi_robot) if rsi else ("egm", egm, egm_robot)))
    config: RsiConfig | EgmConfig = (
        RsiConfig(**where, correction=rsi_correction, mode=rsi_mode,  # type: ignore[arg-type]
                  frame=rsi_frame, timeout_packets=rsi_timeout)  # type: ignore[arg-type]
        if rsi else EgmConfig(**where, mode=egm_mode,  # type: ignore[arg-type]
                              comm_timeout_s=egm_timeout))
    if config.joint_targets:
        config = dataclasses.replace(config, limits=sc.streaming_limits(joint, config.cycle_s))
    _check_correction_limits(correct_max_mm, correct_max_deg)
    return sc.StreamController(handler, config, load_robot(robot), robot, joint, cart, library,
                               name, stream_process, (correct_max_mm, correct_max_deg),
                               calibration,
                               stream_realtime(stream_rt_priority, stream_cpu, stream_mlock),
                               learned_dir, learning_law)
