"""A tracked path over the real RSI seam: the twin's controller and plugcell's link talk UDP
on loopback, in real time (issue 38 §4).

:func:`run_over_udp` is the one set-up the test of the seam
(``tests/sim/test_tracked_path.py``) and the benchmark of its timing
(``benchmarks/dynamic_correction.py``) share: the controller
(:class:`~plugcell.sim.controller.rsi_robot.RsiRobot`, in its own thread, running its path on
the dynamic twin) asks the link (:class:`~plugcell.devices.robot.rsi.link.RsiLink`) every
cycle; the link answers with a :class:`~plugcell.devices.robot.rsi.tracking.TrackingSource`
fed the twin's true reflector before each answer
(:class:`~plugcell.sim.tracked_path.LogFeed`: a perfect tracker one cycle old).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from plugcell.compensation.tracking import TrackingLoop, TrackingSettings
from plugcell.devices.robot.rsi.config import RsiConfig
from plugcell.devices.robot.rsi.link import RsiLink
from plugcell.devices.robot.rsi.tracking import TrackingSource
from plugcell.motion import Trajectory
from plugcell.sim.controller.rsi_robot import RsiRobot
from plugcell.sim.tracked_path import LogFeed, TrackedCell
from plugcell.sim.twin.dynamics import DynamicTwin


@dataclass(frozen=True)
class UdpRun:
    """What a run over UDP leaves to look at (all stopped).

    Attributes
    ----------
    config : RsiConfig
        The link's configuration (its limits bound the offset's steps).
    robot : RsiRobot
        The controller: ``path_done``, ``stopped``, ``stats()`` (its log of every cycle).
    link : RsiLink
        The link: ``latencies`` (µs, packet in → answer out) with ``record_latency``.
    loop : TrackingLoop
        The tracking loop: ``stats``, ``windows`` without tracking.
    source : TrackingSource
        The correction source: ``last`` state.
    feed : LogFeed
        The tracker feed: ``compute_s``, the source's time per answer (s).
    """

    config: RsiConfig
    robot: RsiRobot
    link: RsiLink
    loop: TrackingLoop
    source: TrackingSource
    feed: LogFeed


def run_over_udp(cell: TrackedCell, trajectory: Trajectory, lead_s: float, *,
                 record_latency: bool = False, path_slack_s: float = 60.0,
                 end_timeout_s: float = 30.0,
                 answer: Callable[[LogFeed], Callable[..., Any]] | None = None) -> UdpRun:
    """Run ``trajectory`` on the twin with the tracker in the loop through the RSI link over
    UDP on loopback (module docstring), until the path is done and the source has ended.

    Parameters
    ----------
    cell : TrackedCell
        The twin, its calibration (the loop's model) and start joints.
    trajectory : Trajectory
        The controller's path (``cell.plan``); started 0.5 s after the first packet.
    lead_s : float, s
        The loop's lead ``τ`` (:class:`~plugcell.compensation.tracking.TrackingSettings`).
    record_latency : bool
        The link records each answer's latency.
    path_slack_s, end_timeout_s : float, s
        How long past the path's duration to wait for its end, then for the source's.
    answer : callable, optional
        ``answer(feed)`` is what the link calls each cycle instead of the feed itself
        (e.g. the loop in a thread beside the link); default the feed.

    Returns
    -------
    UdpRun
        Everything stopped.  A wait that runs out does not raise: the run ends there, and
        ``robot.path_done`` and ``source.ended()`` tell.
    """
    arm = DynamicTwin(cell.twin, q0=cell.q0)
    config = RsiConfig(robot_host="127.0.0.1", listen_host="127.0.0.1", listen_port=0,
                       correction="cartesian", mode="absolute", frame="base",
                       timeout_packets=10_000)
    loop = TrackingLoop(cell.model, TrackingSettings(lead_s=lead_s), payload_kg=cell.payload_kg)
    source = TrackingSource(loop, ramp=0.3)
    feed = LogFeed(source, arm)
    with RsiLink(config, feed if answer is None else answer(feed),
                 record_latency=record_latency) as link:
        robot = RsiRobot(arm, dataclasses.replace(config, listen_port=link.address[1]),
                         record=True, path=trajectory, tool=cell.model.tool, path_delay_s=0.5)
        feed.robot = robot
        robot.start()
        try:
            link.wait(lambda lk: robot.path_done or not robot.running,
                      timeout=trajectory.duration + path_slack_s)
            source.finish()
            link.wait(lambda lk: source.ended(), timeout=end_timeout_s)
        finally:
            robot.stop()
    return UdpRun(config, robot, link, loop, source, feed)
