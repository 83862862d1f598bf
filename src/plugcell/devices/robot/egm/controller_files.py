"""What the user loads into the ABB controller, written from one :class:`EgmConfig`.

:func:`controller_files` returns, by file name:

``PlugcellEGM.mod``
    The RAPID module (task T_ROB1): ``EGMGetId``, ``EGMSetupUC`` on the UDP unit device
    with the ``\\CommTimeout``, then by mode ``EGMActJoint`` + ``EGMRunJoint`` (joint
    targets), ``EGMActPose`` + ``EGMRunPose`` (pose targets, work-object frames) or
    ``EGMActMove`` + ``EGMMoveL`` (path corrections on the robot's own path), each with
    the ``\\SampleRate`` and ``EGM_STOP_HOLD``, then ``EGMReset`` — from the templates in
    ``controller/``.
``SIOC_plugcell.cfg``
    The UDP unit device: the Communication topic's Transmission Protocol entry
    (``COM_TRP``) of type ``UDPUC`` with the PC's address and port.
``MOC_plugcell.cfg`` (path corrections only)
    The Motion topic's *External Motion Interface Data* entry (``EXT_MOTION_DATA``) the
    module's ``EGMSetupUC`` names (:class:`ExtMotion`): the proportional position gain,
    the filter's bandwidth, the ramp time, the largest position adjustment (the link's
    ``max_offset``) and, if given, the largest speed factor.  The attribute names are the
    ones RobotWare's configuration lists for that type; plugcell's own joint and pose
    modules use the controller's ``"default"`` entry, which it does not overwrite.
``README.md``
    Where each file goes.

Units: the RAPID side speaks degrees, mm and seconds; the limits are the link's own
(:class:`~..stream.limits.CorrectionLimits`), converted through :mod:`plugcell.io.units`.
"""

from __future__ import annotations

import ipaddress
import re
from dataclasses import dataclass
from pathlib import Path

from plugcell.io.abb_cfg import cfg_text
from plugcell.io.units import DEG, M_PER_MM

from ..stream.files import fill_template, write_files
from .config import EgmConfig

__all__ = ["DEVICE", "ExtMotion", "controller_files", "write_controller_files"]

#: The UDP unit device's name in the configuration and in ``EGMSetupUC``.
DEVICE = "plugcellUC"
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,15}$")
_ACT_RUN = {"joint": ("`EGMActJoint`", "`EGMRunJoint`"),
            "pose": ("`EGMActPose`", "`EGMRunPose`"),
            "pathcorr": ("`EGMActMove`", "`EGMMoveL`")}


@dataclass(frozen=True)
class ExtMotion:
    """The *External Motion Interface Data* entry of a path-correcting EGM
    (``EXT_MOTION_DATA`` in MOC.cfg; ``EGMSetupUC``'s ``ExtConfigName``).

    Attributes
    ----------
    name : str
        The entry's name (a RAPID name): ``EGMSetupUC``'s ``ExtConfigName``.
    kp : float
        ``ext_motion_Kp``: the proportional position gain of the correction (1/s).
    filter_bandwidth_hz : float
        ``ext_motion_filter_bandwidth``: the low-pass filter on the correction (Hz).
    ramp_time_s : float
        ``ramp_time``: how long the controller ramps the correction in and out (s).
    speed_factor : float or None
        ``max_allowed_speed_factor``, if given (the controller's own default otherwise).

    Raises
    ------
    ValueError
        A name that is no RAPID name, or a value that is not a positive finite number.
    """

    name: str = "pathCorr"
    kp: float = 5.0
    filter_bandwidth_hz: float = 20.0
    ramp_time_s: float = 0.5
    speed_factor: float | None = None

    def __post_init__(self) -> None:
        if not _NAME.match(self.name):
            raise ValueError(f"ExtConfigName {self.name!r}: expected a RAPID name of ≤ 16 "
                             "characters")
        for what, v in (("Kp", self.kp), ("filter bandwidth", self.filter_bandwidth_hz),
                        ("ramp time", self.ramp_time_s), ("speed factor", self.speed_factor)):
            if v is None and what == "speed factor":
                continue
            if not (isinstance(v, int | float) and 0 < v < float("inf")):
                raise ValueError(f"External Motion Interface Data {what}: a positive "
                                 f"number, got {v!r}")

    def instance(self, config: EgmConfig) -> dict[str, object]:
        """The MOC instance (attribute → value; SI as the configuration keeps it): the
        largest position adjustment is the link's largest path correction (m)."""
        assert config.limits is not None
        out: dict[str, object] = {
            "name": self.name, "ext_motion_Kp": float(self.kp),
            "ext_motion_filter_bandwidth": float(self.filter_bandwidth_hz),
            "ramp_time": float(self.ramp_time_s),
            "max_external_pos_adjustment": float(max(config.limits.max_offset[:3]))}
        if self.speed_factor is not None:
            out["max_allowed_speed_factor"] = float(self.speed_factor)
        return out


def _limits_text(config: EgmConfig) -> str:
    lim = config.limits
    assert lim is not None
    if config.mode == "joint":
        return (f"{max(lim.max_step) / DEG:g} deg a cycle, {max(lim.max_speed) / DEG:g} "
                f"deg/s, {max(lim.max_offset) / DEG:g} deg in total per joint")
    return (f"{max(lim.max_step[:3]) / M_PER_MM:g} mm a cycle, "
            f"{max(lim.max_speed[:3]) / M_PER_MM:g} mm/s, "
            f"{max(lim.max_offset[:3]) / M_PER_MM:g} mm in total"
            + ("" if config.mode == "pathcorr" else
               f"; {max(lim.max_offset[3:]) / DEG:g} deg of rotation"))


def controller_files(config: EgmConfig, sensor_ip: str, device: str = DEVICE,
                     cond_time_s: float = 1e6,
                     ext_motion: ExtMotion | None = None) -> dict[str, str]:
    """The controller's files for ``config``, by file name (module doc).

    Parameters
    ----------
    config : EgmConfig
        The stream as the PC will run it (its ``listen_port`` is the remote port).
    sensor_ip : str
        The PC's IPv4 address on the controller's network; not ``0.0.0.0``.
    device : str
        The UDP unit device's name (letters, digits, ``_``; ≤ 16 characters).
    cond_time_s : float
        ``\\CondTime`` of ``EGMRunJoint``/``EGMRunPose``: how long the convergence
        condition must hold before the instruction ends (s); the default streams until
        the PC stops.
    ext_motion : ExtMotion, optional
        Path corrections: the External Motion Interface Data entry (default
        :class:`ExtMotion`'s).  Not for joint or pose targets (they use ``"default"``).

    Returns
    -------
    dict of str to str
        File name → text.

    Raises
    ------
    ValueError
        The address is no IPv4 address the controller can send to, the port is 0, or
        the device name is not a RAPID name.
    """
    try:
        ip = ipaddress.ip_address(sensor_ip)
    except ValueError:
        raise ValueError(f"--ip {sensor_ip!r}: expected the PC's IPv4 address") from None
    if ip.is_unspecified or ip.version != 4:
        raise ValueError(f"RemoteAdress {sensor_ip!r}: the controller needs the PC's IPv4 "
                         "address on its network")
    if config.listen_port == 0:
        raise ValueError("RemotePortNumber 0: the controller needs a fixed port")
    if not _NAME.match(device):
        raise ValueError(f"device {device!r}: expected a RAPID name of ≤ 16 characters")
    speed = max(config.limits.max_speed) / DEG if config.mode == "joint" else 20.0
    values = {"sensor_ip": sensor_ip, "port": config.listen_port, "device": device,
              "sample_ms": config.sample_rate_ms, "timeout_s": f"{config.comm_timeout_s:g}",
              "limits": _limits_text(config), "max_speed_deg": f"{speed:g}",
              "cond_time": f"{cond_time_s:g}"}
    if ext_motion is not None and config.mode != "pathcorr":
        raise ValueError("External Motion Interface Data goes with path corrections "
                         "(--mode pathcorr); joint and pose targets use \"default\"")
    act, run = _ACT_RUN[config.mode]
    pkg = __package__
    files = {}
    moc = ""
    if config.mode == "pathcorr":
        ext = ext_motion or ExtMotion()
        values["ext_config"] = ext.name
        files["MOC_plugcell.cfg"] = cfg_text("MOC", {"EXT_MOTION_DATA": [ext.instance(config)]})
        moc = (f"| `MOC_plugcell.cfg` | as `SIOC_plugcell.cfg` | Motion > External Motion "
               f"Interface Data `{ext.name}`, the entry `EGMSetupUC` names: gain Kp "
               f"{ext.kp:g}, filter {ext.filter_bandwidth_hz:g} Hz, ramp "
               f"{ext.ramp_time_s:g} s, largest position adjustment "
               f"{max(config.limits.max_offset[:3]) / M_PER_MM:g} mm |\n")
    files["PlugcellEGM.mod"] = fill_template(pkg, f"PlugcellEGM_{config.mode}.mod", **values)
    files["SIOC_plugcell.cfg"] = fill_template(pkg, "SIOC_plugcell.cfg", **values)
    files["README.md"] = fill_template(pkg, "README.md", mode=config.mode, act=act, run=run,
                                       moc_row=moc, **values)
    return files


def write_controller_files(out: Path, config: EgmConfig, sensor_ip: str,
                           device: str = DEVICE,
                           ext_motion: ExtMotion | None = None) -> list[Path]:
    """Write :func:`controller_files` into the folder ``out`` (made if missing).

    Parameters
    ----------
    out : Path
        The folder.
    config, sensor_ip, device, ext_motion
        As :func:`controller_files`.

    Returns
    -------
    list of Path
        The files written.
    """
    return write_files(out, controller_files(config, sensor_ip, device,
                                             ext_motion=ext_motion))
