"""What the user copies to the KUKA controller, written from one :class:`RsiConfig`.

:func:`controller_files` returns, by file name:

``plugcell_rsi.src``
    The KRL program (``KRC:\\R1\\Program``): a BCO run where the robot stands,
    ``RSI_CREATE`` of the context, ``RSI_ON(#RELATIVE|#ABSOLUTE, #IPO_FAST|#IPO)``,
    ``RSI_MOVECORR()``, ``RSI_OFF()`` — the PC drives; or, for issue 37's mode (b) (the
    robot drives, the PC corrects: ``drives="robot"``), the user's own ``LIN``/``CIRC``/
    ``PTP`` moves between ``RSI_ON`` and ``RSI_OFF`` and a wait for the PC to end its
    correction — from the templates in ``controller/``.
``plugcell_rsi_ethernet.xml``
    The ETHERNET object's configuration (``…\\Config\\User\\Common\\SensorInterface``):
    ``<CONFIG>`` with the PC's ``IP_NUMBER``, ``PORT``, ``SENTYPE`` and ``ONLYSEND``,
    ``<SEND>`` (what the robot reports: RIst, RSol, AIPos, ASPos, MACur, Delay, an input
    word) and ``<RECEIVE>`` (the correction and the output words), with ``HOLDON``
    chosen for the mode: ``0`` for relative corrections (a late packet adds nothing —
    with ``1`` the last step keeps being added while the PC is silent), ``1`` for
    absolute ones (a late packet keeps the offset — with ``0`` the robot would jump back
    to the start).
``plugcell_rsi.rsi.xml``
    The signal flow (RSI 3.x runtime format): ETHERNET1 with the ``Timeout``, AXISCORR1
    (joint) or POSCORR1 (Cartesian) with the limits in mm and degrees, AXISCORRMON1 for
    joint streams, MAP2DIGOUT / DIGIN for the words.
``README.md``
    The diagram described object by object (for RSIVisual / WorkVisual, RSI 4.x
    ``.rsix``) and the copy steps.

The limits on the controller are the link's own (:class:`~.config.CorrectionLimits`),
converted to mm and degrees through :mod:`plugcell.io.units`: the controller clamps at
the same box the PC does, as a second line.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from lxml import etree

from plugcell.io.units import DEG, M_PER_MM

from ..stream.files import fill_template, write_files
from .config import RsiConfig

__all__ = ["IoRouting", "controller_files", "write_controller_files"]

CONTEXT = "plugcell_rsi"
ETHERNET_FILE = "plugcell_rsi_ethernet.xml"
_JOINTS = ("A1", "A2", "A3", "A4", "A5", "A6")
_CART = ("X", "Y", "Z", "A", "B", "C")


@dataclass(frozen=True)
class IoRouting:
    """Which controller I/O the words of the stream are wired to.

    Attributes
    ----------
    outputs : dict of str to int
        Output tag of the stream → first ``$OUT`` index of its word (MAP2DIGOUT).
    input_tag : str or None
        Tag of the input word the robot reports (``DiL``), ``None``: none.
    input_index : int
        First ``$IN`` index of the input word (DIGIN).
    """

    outputs: dict[str, int] | None = None
    input_tag: str | None = None
    input_index: int = 1


def _fill(name: str, **values: object) -> str:
    """The template ``controller/name`` filled (KRL's own ``$`` variables stay)."""
    return fill_template(__package__, name, **values)


def _el(parent: etree._Element, tag: str, **attrib: str) -> etree._Element:
    return etree.SubElement(parent, tag, attrib)


def ethernet_config(config: RsiConfig, sensor_ip: str, io: IoRouting) -> str:
    """The ETHERNET object's XML configuration (module doc).

    Parameters
    ----------
    config : RsiConfig
        The stream (port, SENTYPE, correction, mode, outputs).
    sensor_ip : str
        The PC's address on the RSI network: ``IP_NUMBER``.
    io : IoRouting
        The input word, if any.

    Returns
    -------
    str
        The file's text.
    """
    root = etree.Element("ROOT")
    cfg = _el(root, "CONFIG")
    for tag, text in (("IP_NUMBER", sensor_ip), ("PORT", str(config.listen_port)),
                      ("SENTYPE", config.sentype), ("ONLYSEND", "FALSE")):
        _el(cfg, tag).text = text
    root.append(etree.Comment(" written by plugcell rsi files: the PC (sensor) listens at "
                              "IP_NUMBER:PORT "))
    send = _el(_el(root, "SEND"), "ELEMENTS")
    for tag, type_ in (("DEF_RIst", "DOUBLE"), ("DEF_RSol", "DOUBLE"), ("DEF_AIPos", "DOUBLE"),
                       ("DEF_ASPos", "DOUBLE"), ("DEF_MACur", "DOUBLE"), ("DEF_Delay", "LONG")):
        _el(send, "ELEMENT", TAG=tag, TYPE=type_, INDX="INTERNAL")
    if io.input_tag:
        _el(send, "ELEMENT", TAG=io.input_tag, TYPE="LONG", INDX="1")
    recv_section = _el(root, "RECEIVE")
    relative = config.mode == "relative"
    recv_section.append(etree.Comment(
        " HOLDON: relative corrections use 0 (a late packet adds nothing; with 1 the last "
        "step keeps being added while the PC is silent: drift), absolute corrections use 1 "
        "(a late packet keeps the offset; with 0 the robot would jump back to the start). "))
    recv = _el(recv_section, "ELEMENTS")
    hold = "0" if relative else "1"
    kind, axes = ("AKorr", _JOINTS) if config.correction == "joint" else ("RKorr", _CART)
    for i, axis in enumerate(axes, start=1):
        _el(recv, "ELEMENT", TAG=f"{kind}.{axis}", TYPE="DOUBLE", INDX=str(i), HOLDON=hold)
    for j, out in enumerate(config.outputs, start=7):
        _el(recv, "ELEMENT", TAG=out.tag, TYPE="LONG", INDX=str(j), HOLDON="1")
    etree.indent(root, space="   ")
    return etree.tostring(root, encoding="unicode") + "\n"


def _param(parent: etree._Element, name: str, pid: int, value: str) -> None:
    _el(parent, "Parameter", Name=name, ParamID=str(pid), ParamValue=value)


def signal_flow(config: RsiConfig, io: IoRouting) -> str:
    """The RSI 3.x signal flow (``.rsi.xml``, the RSIObjects the runtime loads).

    Parameters
    ----------
    config : RsiConfig
        The stream (correction, limits, Timeout, outputs).
    io : IoRouting
        The I/O words' indices.

    Returns
    -------
    str
        The file's text.
    """
    xsi = "http://www.w3.org/2001/XMLSchema-instance"
    root = etree.Element("RSIObjects", nsmap={"xsi": xsi})
    root.set(f"{{{xsi}}}noNamespaceSchemaLocation",
             "/Roboter/Config/System/Common/Schemes/RSIContext.xsd")

    def obj(type_: str, type_id: int, obj_id: str) -> etree._Element:
        return _el(root, "RSIObject", ObjType=type_, ObjTypeID=str(type_id), ObjID=obj_id)

    eth = obj("ETHERNET", 64, "ETHERNET1")
    p = _el(eth, "Parameters")
    _el(p, "Parameter", Name="ConfigFile", ParamID="1", ParamValue=ETHERNET_FILE,
        IsRuntime="false")
    _param(p, "Timeout", 1, str(config.timeout_packets))
    _param(p, "Flag", 4, "1")
    _param(p, "Precision", 8, "4")
    lim = config.limits
    if config.correction == "joint":
        corr = obj("AXISCORR", 33, "AXISCORR1")
        inputs = _el(corr, "Inputs")
        for i in range(1, 7):
            _el(inputs, "Input", InIdx=str(i), OutObjID="ETHERNET1", OutIdx=str(i))
        p = _el(corr, "Parameters")
        for i, a in enumerate(_JOINTS):
            _param(p, f"LowerLim{a}", 1 + i, f"{-lim.max_offset[i] / DEG:.4f}")
        for i, a in enumerate(_JOINTS):
            _param(p, f"UpperLim{a}", 13 + i, f"{lim.max_offset[i] / DEG:.4f}")
        mon = obj("AXISCORRMON", 82, "AXISCORRMON1")
        p = _el(mon, "Parameters")
        for i, a in enumerate(_JOINTS):  # beyond the clamp box: RSI stops
            _param(p, f"Max{a}", 1 + i, f"{1.1 * lim.max_offset[i] / DEG:.4f}")
    else:
        corr = obj("POSCORR", 27, "POSCORR1")
        inputs = _el(corr, "Inputs")
        for i in range(1, 7):
            _el(inputs, "Input", InIdx=str(i), OutObjID="ETHERNET1", OutIdx=str(i))
        p = _el(corr, "Parameters")
        for i, a in enumerate("XYZ"):
            _param(p, f"LowerLim{a}", 1 + i, f"{-lim.max_offset[i] / M_PER_MM:.3f}")
        for i, a in enumerate("XYZ"):
            _param(p, f"UpperLim{a}", 4 + i, f"{lim.max_offset[i] / M_PER_MM:.3f}")
        _param(p, "MaxRotAngle", 7, f"{max(lim.max_offset[3:]) / DEG:.4f}")
        # RefCorrSys: 1 the base frame, 2 the TCP (tool) frame
        _el(p, "Parameter", Name="RefCorrSys", ParamID="1",
            ParamValue="1" if config.frame == "base" else "2", IsRuntime="false")
    outputs = io.outputs or {}
    for j, out in enumerate(config.outputs, start=7):
        if out.tag not in outputs:
            continue
        m = obj("MAP2DIGOUT", 14, f"MAP2DIGOUT{j - 6}")
        _el(_el(m, "Inputs"), "Input", InIdx="1", OutObjID="ETHERNET1", OutIdx=str(j))
        p = _el(m, "Parameters")
        _param(p, "Index", 1, str(outputs[out.tag]))
        _param(p, "DataSize", 2, "2" if out.bits > 1 else "0")
    if io.input_tag:  # DIGIN1 → ETHERNET1 input 1 (the SEND element of INDX 1)
        eth.insert(0, etree.Element("Inputs"))
        _el(eth[0], "Input", InIdx="1", OutObjID="DIGIN1", OutIdx="1")
        d = obj("DIGIN", 29, "DIGIN1")
        p = _el(d, "Parameters")
        _param(p, "Index", 1, str(io.input_index))
        _param(p, "DataSize", 2, "2")
    etree.indent(root, space="  ")
    return ('<?xml version="1.0" encoding="UTF-8" standalone="yes"?>\n'
            + etree.tostring(root, encoding="unicode") + "\n")


def krl_program(config: RsiConfig, drives: str = "pc", settle_s: float = 1.0) -> str:
    """The KRL program ``plugcell_rsi.src`` for ``config``: the PC drives (``RSI_MOVECORR``)
    or the robot drives (its own moves between ``RSI_ON`` and ``RSI_OFF``, then a wait of
    ``settle_s`` s) — :func:`controller_files`, whose checks it relies on."""
    relative = config.mode == "relative"
    return _fill("plugcell_rsi.src" if drives == "pc" else "plugcell_rsi_path.src",
        cycle_ms=f"{config.cycle_s * 1000:g}",
        correction_text=("joint corrections AKorr A1..A6 in degrees"
                         if config.correction == "joint"
                         else "Cartesian corrections RKorr X Y Z (mm) A B C (deg)"),
        mode_text="#RELATIVE" if relative else "#ABSOLUTE",
        mode_note=("each packet carries this cycle's step; HOLDON=0 in the ethernet file, "
                   "so a late packet adds nothing" if relative else
                   "each packet carries the whole offset from the start; HOLDON=1, so a "
                   "late packet keeps it"),
        mode_krl="RELATIVE" if relative else "ABSOLUTE",
        cycle=config.cycle, context=f"{CONTEXT}.rsi", ethernet_file=ETHERNET_FILE,
        end_note=("plugcell's last steps sum its correction back to zero (relative)"
                  if relative else "plugcell ramps the offset it sends back to zero "
                  "(absolute)"),
        settle_s=f"{settle_s:g}")


def controller_files(config: RsiConfig, sensor_ip: str, io: IoRouting | None = None,
                     drives: str = "pc", settle_s: float = 1.0) -> dict[str, str]:
    """The controller's files for ``config``, by file name (module doc).

    Parameters
    ----------
    config : RsiConfig
        The stream as the PC will run it (its ``listen_port`` is the controller's
        ``PORT``).
    sensor_ip : str
        The PC's address on the RSI network (``IP_NUMBER``); not ``0.0.0.0``.
    io : IoRouting, optional
        Where the output words and the input word are wired (default: outputs at
        ``$OUT[1…]``, no input word).
    drives : {"pc", "robot"}
        Who drives (issue 37 §1): ``"pc"`` — the KRL program holds the robot where it
        stands and follows the PC (``RSI_MOVECORR()``); ``"robot"`` — the program runs its
        own moves between ``RSI_ON`` and ``RSI_OFF`` and the PC superimposes corrections
        (the robot service's ``CORRECT``), then waits ``settle_s`` seconds for the PC to
        end its correction before ``RSI_OFF``.
    settle_s : float
        ``drives="robot"``: that wait (s).

    Returns
    -------
    dict of str to str
        File name → text.

    Raises
    ------
    ValueError
        ``sensor_ip`` is no address the controller can send to, the port is 0, or
        ``drives``/``settle_s`` is not one of the above.
    """
    import ipaddress

    if drives not in ("pc", "robot"):
        raise ValueError(f"drives {drives!r}: expected 'pc' or 'robot'")
    if not (0 <= settle_s <= 60):
        raise ValueError(f"settle {settle_s!r}: expected 0..60 seconds")

    ip = ipaddress.ip_address(sensor_ip)
    if ip.is_unspecified or ip.version != 4:
        raise ValueError(f"IP_NUMBER {sensor_ip!r}: the controller needs the PC's IPv4 "
                         "address on the RSI network")
    if config.listen_port == 0:
        raise ValueError("PORT 0: the controller needs a fixed port")
    io = io or IoRouting(outputs={o.tag: 1 + 16 * k for k, o in enumerate(config.outputs)})
    relative = config.mode == "relative"
    src = krl_program(config, drives, settle_s)
    readme = _fill("README.md",
        program=("the KRL program: BCO run where the robot stands, `RSI_CREATE`, `RSI_ON`, "
                 "`RSI_MOVECORR()` (the PC drives), `RSI_OFF`" if drives == "pc" else
                 "the KRL program: your start pose, `RSI_CREATE`, `RSI_ON`, your own moves "
                 "(the robot drives, the PC corrects), a wait for the PC to end its "
                 "correction, `RSI_OFF`"),
        sensor_ip=sensor_ip, port=config.listen_port, sentype=config.sentype,
        correction=config.correction, mode=config.mode, cycle=config.cycle,
        cycle_ms=f"{config.cycle_s * 1000:g}", timeout=config.timeout_packets,
        timeout_ms=f"{config.timeout_s * 1000:g}", hold="0" if relative else "1",
        corr_object=("AXISCORR1 (inputs 1-6: A1..A6 in degrees), AXISCORRMON1"
                     if config.correction == "joint"
                     else "POSCORR1 (inputs 1-6: X Y Z in mm, A B C in degrees)"),
        outputs=", ".join(f"{o.tag} → MAP2DIGOUT (from $OUT[{io.outputs.get(o.tag, '-')}])"
                          for o in config.outputs if io.outputs) or "none",
        input_word=(f"{io.input_tag} ← DIGIN1 (from $IN[{io.input_index}])"
                    if io.input_tag else "none"))
    return {f"{CONTEXT}.src": src, ETHERNET_FILE: ethernet_config(config, sensor_ip, io),
            f"{CONTEXT}.rsi.xml": signal_flow(config, io), "README.md": readme}


def write_controller_files(out: Path, config: RsiConfig, sensor_ip: str,
                           io: IoRouting | None = None, drives: str = "pc",
                           settle_s: float = 1.0) -> list[Path]:
    """Write :func:`controller_files` into the folder ``out`` (made if missing).

    Parameters
    ----------
    out : Path
        The folder.
    config, sensor_ip, io, drives, settle_s
        As :func:`controller_files`.

    Returns
    -------
    list of Path
        The files written.
    """
    # KRL and the controller's Windows side expect CRLF line ends
    return write_files(out, controller_files(config, sensor_ip, io, drives, settle_s))
