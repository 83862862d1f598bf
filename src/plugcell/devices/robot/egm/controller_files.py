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
``README.md``
    Where each file goes.

Units: the RAPID side speaks degrees, mm and seconds; the limits are the link's own
(:class:`~..stream.limits.CorrectionLimits`), converted through :mod:`plugcell.io.units`.
"""

from __future__ import annotations

import ipaddress
import re
from pathlib import Path

from plugcell.io.units import DEG, M_PER_MM

from ..stream.files import fill_template, write_files
from .config import EgmConfig

__all__ = ["DEVICE", "controller_files", "write_controller_files"]

#: The UDP unit device's name in the configuration and in ``EGMSetupUC``.
DEVICE = "plugcellUC"
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,15}$")
_ACT_RUN = {"joint": ("`EGMActJoint`", "`EGMRunJoint`"),
            "pose": ("`EGMActPose`", "`EGMRunPose`"),
            "pathcorr": ("`EGMActMove`", "`EGMMoveL`")}


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
                     cond_time_s: float = 1e6) -> dict[str, str]:
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
    act, run = _ACT_RUN[config.mode]
    pkg = __package__
    return {
        "PlugcellEGM.mod": fill_template(pkg, f"PlugcellEGM_{config.mode}.mod", **values),
        "SIOC_plugcell.cfg": fill_template(pkg, "SIOC_plugcell.cfg", **values),
        "README.md": fill_template(pkg, "README.md", mode=config.mode, act=act, run=run,
                                   **values),
    }


def write_controller_files(out: Path, config: EgmConfig, sensor_ip: str,
                           device: str = DEVICE) -> list[Path]:
    """Write :func:`controller_files` into the folder ``out`` (made if missing).

    Parameters
    ----------
    out : Path
        The folder.
    config, sensor_ip, device
        As :func:`controller_files`.

    Returns
    -------
    list of Path
        The files written.
    """
    return write_files(out, controller_files(config, sensor_ip, device))
