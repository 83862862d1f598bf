"""The robot service's commands of mode (b), *the robot drives, the PC corrects*.

A robot streamed over RSI or EGM (:mod:`.streamed`) runs its own program on the
controller — KRL moves between ``RSI_ON`` and ``RSI_OFF``, RAPID's ``EGMMoveL`` — and the
service superimposes corrections on that path (:mod:`.stream.correcting`):

==============  ==========  ==================  ==============================================
command         type        input → output      does
==============  ==========  ==================  ==============================================
CORRECT         NoData      String[*]           ``[source, "key=value", …]``: start a
                                                correction; option ``Wait``: until it ended
CORRECT_SET     NoData      Double[6]           the running correction's offset (the hook
                                                of a tracker's loop)
CORRECT_END     NoData      —                   ramp it out, and wait for the end
CORRECT_STATUS  SingleData  → Double[7]         ``[b, o1…o6]``: the blend factor and the
                                                offset commanded (mm, deg; joints deg)
==============  ==========  ==================  ==============================================

Sources: ``offset`` (``offset=X,Y,Z,A,B,C``: mm and degrees, or six joint degrees with
``frame=joints``), ``compensation`` (``calibration=PARAMS.json``: the calibration's
correction at the path's joints, every cycle) and ``external`` (the offset comes from
``CORRECT_SET``).  Keys of every source: ``frame=base|tool|joints|path`` (default: the
stream's own — base for RSI joint or base-frame corrections, tool for tool-frame ones,
path for EGM), ``ramp=S`` (0.5 s, in and out), ``duration=S`` (then the ramp out;
default: until ``CORRECT_END``), ``payload_kg=M`` (compensation), ``tcp=X,Y,Z,A,B,C``
(mm, degrees: the controller's TCP, KUKA's ``$TOOL``, when it is not the description's
tool — the point Cartesian corrections move).  It ends with zero
corrections (relative) or the offset ramped back to zero (absolute).  Units: mm and
degrees here, SI inside (:mod:`plugcell.io.units`).
"""

from __future__ import annotations

import asyncio
import time
from typing import Any

import numpy as np

from plugcell.devices.robot.stream.correcting import SOURCES, CorrectionSpec, correction_space
from plugcell.framework.messages import Command, CommandTypes, DataTypes
from plugcell.framework.service import DeviceError
from plugcell.io.units import DEG, M_PER_MM

__all__ = ["CORRECT_COMMANDS", "PathCorrections"]

_D, _S = DataTypes.Double, DataTypes.String

#: The commands (declared by the robot service beside Table 7-1's).
CORRECT_COMMANDS = (
    Command(name="CORRECT", type=CommandTypes.NoData, input_data_type=_S,
            input_data_size=(-1,), timeout=24 * 3600.0,
            info="mode (b), the robot drives: superimpose a correction on the controller's own "
                 "path: [offset|compensation|external, 'key=value', ...]; option 'Wait': "
                 "until it ended"),
    Command(name="CORRECT_SET", type=CommandTypes.NoData, input_data_type=_D,
            input_data_size=(6,), info="the running correction's offset (mm, deg; joints deg)"),
    Command(name="CORRECT_END", type=CommandTypes.NoData, timeout=120.0,
            info="ramp the running correction out and wait for its end"),
    Command(name="CORRECT_STATUS", type=CommandTypes.SingleData, output_data_type=_D,
            output_data_size=(7,),
            info="[blend 0..1, offset commanded x6 (mm, deg; joints deg)]"),
)
#: How often a waiting command looks at the correction (s).
POLL_S = 0.02
_KEYS = ("offset", "frame", "ramp", "duration", "calibration", "payload_kg", "tcp")


def _scale(frame: str) -> np.ndarray:
    """Robot units → SI of a frame's six values: joints in degrees; X, Y, Z in mm then
    A, B, C in degrees."""
    if frame == "joints":
        return np.full(6, DEG)
    return np.array([M_PER_MM] * 3 + [DEG] * 3)


class PathCorrections:
    """The commands of mode (b) on a robot service's streamed controller (module doc).

    Parameters
    ----------
    controller : StreamController or None
        The service's link when it is a streamed robot (``None``: it is not, and every
        command says so).
    robot : str
        The robot (a shipped name or a description file): the nominal model.
    """

    def __init__(self, controller: Any, robot: str) -> None:
        self.controller = controller
        self.robot = robot
        self.frame = ""  # the running correction's frame (CORRECT_SET's values)

    async def perform(self, command: Command, option: str, data: Any) -> Any:
        """Carry out one of :data:`CORRECT_COMMANDS`; its output (``None`` for NoData).

        Raises
        ------
        DeviceError
            Why not: not a streamed robot, a program running on the PC, a bad source, key,
            frame or offset, an offset beyond the limits, no correction running, or the
            correction's failure (the stream's reason).
        """
        c = self.controller
        if c is None:
            raise DeviceError(f"{command.name}: corrections on the controller's own path need "
                              "a robot streamed over RSI or EGM (rsi=HOST:PORT or "
                              "egm=HOST:PORT); this controller runs the programs itself")
        corrector = c.corrector
        try:
            match command.name:
                case "CORRECT":
                    return await self._start(option, data)
                case "CORRECT_SET":
                    frame = self.frame or "base"
                    values = self._within(np.asarray(data, dtype=float).reshape(-1), frame)
                    await asyncio.to_thread(corrector.set_offset, values * _scale(frame))
                    return None
                case "CORRECT_END":
                    last = await asyncio.to_thread(corrector.poll)
                    if last is not None:
                        raise RuntimeError(f"no correction runs (the last: "
                                           f"{last or 'ended, ramped out'})")
                    await asyncio.to_thread(corrector.finish)
                    return await self._wait(command.timeout - 1.0)
                case "CORRECT_STATUS":
                    blend, offset = await asyncio.to_thread(corrector.status)
                    space = correction_space(c.config)
                    return np.concatenate([[blend], offset / _scale(space)])
        except (ValueError, RuntimeError) as exc:
            raise DeviceError(str(exc)) from None
        raise DeviceError(f"{command.name} is not implemented")  # pragma: no cover

    def spec(self, items: list[str]) -> CorrectionSpec:
        """The :class:`CorrectionSpec` of a ``CORRECT`` request's strings.

        Raises
        ------
        ValueError
            An unknown source or key, a value that does not read, an offset beyond the
            service's largest correction: the reason.
        """
        if not items or items[0].strip() not in SOURCES:
            given = items[0].strip() if items else ""
            raise ValueError(f"unknown correction source {given!r}: one of "
                             f"{', '.join(SOURCES)}")
        source = items[0].strip()
        keys: dict[str, str] = {}
        for item in items[1:]:
            key, sep, text = item.partition("=")
            key = key.strip()
            if not sep or key not in _KEYS:
                raise ValueError(f"bad CORRECT item {item!r}: expected key=value with a key "
                                 f"of {', '.join(_KEYS)}")
            keys[key] = text.strip()
        space = correction_space(self.controller.config)
        frame = keys.get("frame", space if space != "joints" else "base")
        values = self._within(_numbers(keys.get("offset", "0,0,0,0,0,0"), "offset", 6),
                              frame)
        space_limit = self._limit(space) * _scale(space)
        return CorrectionSpec(
            source, offset=tuple(values * _scale(frame)),
            frame=frame, ramp_s=_number(keys.get("ramp", "0.5"), "ramp"),
            duration_s=(_number(keys["duration"], "duration") if "duration" in keys
                        else None),
            max_offset=tuple(space_limit), robot=self.robot,
            calibration=keys.get("calibration", ""),
            payload_kg=(_number(keys["payload_kg"], "payload_kg") if "payload_kg" in keys
                        else None),
            tcp=(tuple(_numbers(keys["tcp"], "tcp", 6) * _scale("base")) if "tcp" in keys
                 else None))

    def _limit(self, frame: str) -> np.ndarray:
        """The largest correction per axis in ``frame``'s robot units (mm, °)."""
        mm, deg = self.controller.correct_max
        return np.full(6, deg) if frame == "joints" else np.array([mm] * 3 + [deg] * 3)

    def _within(self, values: np.ndarray, frame: str) -> np.ndarray:
        """``values`` (robot units, in ``frame``), or ``ValueError`` naming the axis beyond
        the service's largest correction."""
        limit = self._limit(frame)
        over = np.flatnonzero(np.abs(values) > limit)
        if len(over):
            i = int(over[0])
            unit = "mm" if frame != "joints" and i < 3 else "°"
            axis = (f"A{i + 1}" if frame == "joints" else "XYZABC"[i])
            raise ValueError(f"offset {axis} {values[i]:g} {unit} beyond the largest "
                             f"correction {limit[i]:g} {unit} (correct_max_mm, "
                             f"correct_max_deg)")
        return values

    async def _start(self, option: str, data: Any) -> None:
        if option not in ("", "Wait"):
            raise ValueError(f"unknown option {option!r}: '' (start the correction) or "
                             "'Wait' (until it ended)")
        c = self.controller
        busy = c.runner.busy_reason()
        if busy:
            raise RuntimeError(f"{busy}: the PC drives; a correction needs the controller "
                               "running its own program")
        spec = self.spec([str(s) for s in np.asarray(data, dtype=object).reshape(-1)])
        await asyncio.to_thread(c.corrector.start, spec)
        self.frame = spec.frame
        if option == "Wait":
            return await self._wait(spec.timeout_s)
        return None

    async def _wait(self, timeout: float) -> None:
        """Until the correction ended: ``None``, or ``RuntimeError`` with why it failed."""
        end = time.monotonic() + timeout
        while (outcome := await asyncio.to_thread(self.controller.corrector.poll)) is None:
            if time.monotonic() > end:
                raise RuntimeError(f"the correction did not end within {timeout:g} s")
            await asyncio.sleep(POLL_S)
        if outcome:
            raise RuntimeError(outcome)
        return None


def _number(text: str, what: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"{what}={text!r}: expected a number") from None


def _numbers(text: str, what: str, count: int) -> np.ndarray:
    parts = [p for p in text.replace(" ", ",").split(",") if p]
    values = np.array([_number(p, what) for p in parts], dtype=float)
    if len(values) != count or not np.isfinite(values).all():
        raise ValueError(f"{what}={text!r}: expected {count} finite numbers separated by commas")
    return values
