"""RSI's packets: the robot's ``<Rob Type="KUKA">`` in, the sensor's ``<Sen>`` out.

The controller sends, every cycle, one UDP datagram of the elements its ethernet
configuration lists under ``SEND`` (KUKA RSI manual, "Configuration file for
Ethernet")::

    <Rob Type="KUKA">
      <RIst X="445.0" Y="0.0" Z="900.0" A="180.0" B="0.0" C="180.0"/>   actual TCP (mm, deg)
      <RSol …/>                                                         set-point TCP
      <AIPos A1="0.0" A2="-90.0" … A6="0.0"/>                           actual axes (deg)
      <ASPos …/>  <EIPos E1=… /> <MACur A1=… />                         set-point, external
      <Delay D="0"/>                                                    late packets so far
      <Digout o1="0" o2="1" o3="0"/>  <DiL>5</DiL>                      routed I/O
      <IPOC>4208711356</IPOC>                                           the cycle's stamp
    </Rob>

and expects, before its next cycle, one ``<Sen Type="SENTYPE">`` echoing the IPOC::

    <Sen Type="ImFree"><AKorr A1="0.01" … A6="0"/><DiO>5</DiO><IPOC>4208711356</IPOC></Sen>

:func:`parse_rob` reads a packet with lxml (a parser without DTDs, entities or network,
documents with a DOCTYPE refused) into a :class:`RobotState` in SI — positions
``mm → m`` and ``deg → rad`` through :mod:`plugcell.io.units` — and raises
:class:`PacketError` with the reason (its ``kind``: ``malformed``, ``oversized`` or
``foreign``) for anything else.  :func:`encode_sen` writes the answer from SI values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from lxml import etree
from numpy.typing import NDArray

from plugcell.io.units import DEG, M_PER_MM, MM_PER_M
from plugcell.kinematics.rotations import rpy_to_matrix

from ..stream.errors import PacketError

Array = NDArray[np.float64]

__all__ = [
    "CARTESIAN_AXES",
    "JOINT_AXES",
    "PacketError",
    "RobotState",
    "encode_sen",
    "parse_rob",
]

#: Attribute names of the Cartesian elements (RIst, RSol, RKorr) and the joint ones.
CARTESIAN_AXES = ("X", "Y", "Z", "A", "B", "C")
JOINT_AXES = ("A1", "A2", "A3", "A4", "A5", "A6")
EXTERNAL_AXES = ("E1", "E2", "E3", "E4", "E5", "E6")
#: The largest IPOC accepted (the controller's is an unsigned 32- or 64-bit counter).
IPOC_MAX = (1 << 63) - 1
#: The largest late-packet count accepted (the controller's is a 32-bit integer).
DELAY_MAX = (1 << 31) - 1
#: A robot packet with more elements than this is foreign (RSI allows 64 channels).
MAX_ELEMENTS = 128

# SI per robot unit of each standard element's attributes.
_CART_SCALE = np.array([M_PER_MM] * 3 + [DEG] * 3)
_JOINT_SCALE = np.full(6, DEG)
_STANDARD: dict[str, tuple[tuple[str, ...], Array | None]] = {
    "RIst": (CARTESIAN_AXES, _CART_SCALE),
    "RSol": (CARTESIAN_AXES, _CART_SCALE),
    "AIPos": (JOINT_AXES, _JOINT_SCALE),
    "ASPos": (JOINT_AXES, _JOINT_SCALE),
    "MACur": (JOINT_AXES, None),  # percent of the motor's maximum current
    "EIPos": (EXTERNAL_AXES, None),  # external axes: robot units (deg or mm by axis)
    "ESPos": (EXTERNAL_AXES, None),
    "MECur": (EXTERNAL_AXES, None),
}

_AXIS_SETS = {tag: set(axes) for tag, (axes, _) in _STANDARD.items()}
#: SI-per-robot-unit rows of the standard elements, by the order a packet lists them.
_SCALES: dict[tuple[str, ...], Array] = {}

_PARSER = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False,
                          huge_tree=False, remove_comments=True, remove_pis=True)


@dataclass(frozen=True)
class RobotState:
    """One ``<Rob>`` packet, in SI.

    Attributes
    ----------
    ipoc : int
        The controller's stamp of the cycle (ms); the answer must echo it.
    joints : ndarray, shape (6,) or None
        ``AIPos``, the actual axis positions (rad).
    joints_setpoint : ndarray, shape (6,) or None
        ``ASPos``, the set-point axis positions (rad).
    tcp : ndarray, shape (6,) or None
        ``RIst``, the actual TCP: x, y, z (m), then KUKA's A, B, C (rad; rotations about
        Z, Y, X: ``R = Rz(A)·Ry(B)·Rx(C)``).
    tcp_setpoint : ndarray, shape (6,) or None
        ``RSol``, the set-point TCP, like ``tcp``.
    motor_currents : ndarray, shape (6,) or None
        ``MACur``: percent of each motor's maximum current, as the controller reports it.
    external : ndarray, shape (6,) or None
        ``EIPos``: external axes, in the controller's units (deg or mm per axis).
    delay : int or None
        ``Delay D``: late sensor packets the controller has counted in this RSI session.
    signals : dict
        Every other element: ``<DiL>5</DiL>`` → ``{"DiL": 5.0}``, ``<Digout o1="1"/>``
        → ``{"Digout": {"o1": 1.0}}``, as the controller sent them (no unit conversion).
    """

    ipoc: int
    joints: Array | None = None
    joints_setpoint: Array | None = None
    tcp: Array | None = None
    tcp_setpoint: Array | None = None
    motor_currents: Array | None = None
    external: Array | None = None
    external_setpoint: Array | None = None
    delay: int | None = None
    signals: dict[str, float | dict[str, float]] = field(default_factory=dict)

    def tcp_matrix(self) -> Array:
        """The actual TCP as a 4×4 homogeneous transform (m).

        ``T = [Rz(A)·Ry(B)·Rx(C), (x, y, z)ᵀ; 0, 1]`` — KUKA's A, B, C are roll-pitch-yaw
        with the yaw first.

        Returns
        -------
        ndarray, shape (4, 4)
            The transform.

        Raises
        ------
        ValueError
            The packet carried no ``RIst``.
        """
        if self.tcp is None:
            raise ValueError("the robot's packet carries no RIst (add DEF_RIst to SEND)")
        T = np.eye(4)
        T[:3, :3] = rpy_to_matrix(self.tcp[5], self.tcp[4], self.tcp[3])
        T[:3, 3] = self.tcp[:3]
        return T


def _number(tag: str, name: str, text: str | None) -> float:
    try:
        v = float(text)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise PacketError("malformed", f"<{tag}> {name}={text!r} is not a number") from None
    if not math.isfinite(v):
        raise PacketError("malformed", f"<{tag}> {name}={text!r} is not finite")
    return v


def parse_rob(data: bytes, max_bytes: int = 4096) -> RobotState:
    """One datagram → :class:`RobotState` (SI), or :class:`PacketError` saying why.

    Parameters
    ----------
    data : bytes
        The datagram as received.
    max_bytes : int
        Larger datagrams are refused as oversized before any parsing.

    Returns
    -------
    RobotState
        The packet's values: positions in m and rad, the rest as sent.

    Raises
    ------
    PacketError
        ``oversized``: more than ``max_bytes``; ``malformed``: not well-formed XML, an
        element nested deeper than one level, a missing, repeated or unreadable value;
        ``foreign``: XML but not ``<Rob Type="KUKA">`` (or a DOCTYPE, or too many
        elements).
    """
    return read_rob(rob_root(data, max_bytes))


def rob_root(data: bytes, max_bytes: int = 4096) -> etree._Element:
    """The datagram's XML root, checked to be a ``<Rob Type="KUKA">`` of a bounded size
    (:func:`parse_rob`'s first stage; its ``PacketError`` for anything else)."""
    if len(data) > max_bytes:
        raise PacketError("oversized", f"{len(data)} bytes > {max_bytes}")
    try:
        root = etree.fromstring(data, _PARSER)
    except etree.XMLSyntaxError as exc:
        raise PacketError("malformed", f"not well-formed XML: {exc}") from None
    if root.tag != "Rob" or root.get("Type") != "KUKA":
        raise PacketError("foreign", f"root <{root.tag} Type={root.get('Type')!r}>, "
                          "expected <Rob Type=\"KUKA\">")
    if root.getroottree().docinfo.doctype:
        raise PacketError("foreign", "a robot packet has no DOCTYPE")
    if len(root) > MAX_ELEMENTS:
        raise PacketError("foreign", f"{len(root)} elements > {MAX_ELEMENTS}")
    return root


def read_rob(root: etree._Element) -> RobotState:
    """The :class:`RobotState` of a ``<Rob>`` root (:func:`parse_rob`'s second stage)."""
    flat: list[float] = []  # the six values of each standard element, in ``order``
    order: list[str] = []
    signals: dict[str, float | dict[str, float]] = {}
    seen: set[str] = set()
    ipoc: int | None = None
    delay: int | None = None
    for el in root:
        tag = el.tag
        if type(tag) is not str:  # an entity reference or a processing instruction
            raise PacketError("malformed", "a robot packet holds elements only")
        if not (tag.isascii() and tag.isidentifier()):  # RSI's tags are ASCII names
            raise PacketError("foreign", f"element {tag[:32]!r} is no RSI tag")
        if tag in seen:
            raise PacketError("malformed", f"<{tag}> appears twice")
        seen.add(tag)
        if len(el):
            raise PacketError("malformed", f"<{tag}> has child elements")
        standard = _STANDARD.get(tag)
        if standard is not None:
            attrs = dict(el.items())
            if attrs.keys() != _AXIS_SETS[tag]:
                raise PacketError("malformed", f"<{tag}> has {sorted(attrs)}, "
                                  f"expected {list(standard[0])}")
            try:  # the fast path; finiteness is checked once for all elements below
                flat.extend([float(attrs[a]) for a in standard[0]])
            except ValueError:
                for a in standard[0]:  # the slow path names the value
                    _number(tag, a, attrs[a])
            order.append(tag)
        elif tag == "IPOC":
            ipoc = _ipoc((el.text or "").strip())
        elif tag == "Delay":
            delay = _delay(_number(tag, "D", el.get("D")))
        elif len(el.attrib):
            attrs = dict(el.items())
            if not all(k.isascii() and k.isidentifier() for k in attrs):
                raise PacketError("foreign", f"<{tag}> has an attribute that is no RSI name")
            signals[tag] = {k: _number(tag, k, v) for k, v in attrs.items()}
        else:
            signals[tag] = _number(tag, "text", (el.text or "").strip())
    if ipoc is None:
        raise PacketError("malformed", "no <IPOC>")
    v = np.array(flat).reshape(len(order), 6)
    if not np.isfinite(v).all():
        i, j = (int(x[0]) for x in np.nonzero(~np.isfinite(v)))
        raise PacketError("malformed", f"<{order[i]}> {_STANDARD[order[i]][0][j]}="
                          f"{v[i, j]} is not finite")
    return robot_state(ipoc, tuple(order), v, delay, signals)


def _ipoc(text: str) -> int:
    """The IPOC of ``<IPOC>``'s stripped text."""
    if not text.isdigit() or not text.isascii():
        raise PacketError("malformed", f"<IPOC> {text[:32]!r} is not a counter")
    ipoc = int(text)
    if ipoc > IPOC_MAX:
        raise PacketError("malformed", f"<IPOC> {text[:32]} out of range")
    return ipoc


def _delay(d: float) -> int:
    """The count of ``<Delay D>``'s finite value ``d``."""
    if not 0 <= d <= DELAY_MAX or d != int(d):
        raise PacketError("malformed", f"<Delay> D={d} is no count")
    return int(d)


def scale_of(order: tuple[str, ...]) -> Array:
    """SI per robot unit of the standard elements listed in ``order``, shape (n, 6)."""
    scale = _SCALES.get(order)
    if scale is None:
        scale = np.array([_STANDARD[t][1] if _STANDARD[t][1] is not None
                          else np.ones(6) for t in order]).reshape(len(order), 6)
        if len(_SCALES) < 64:  # the orders a controller uses: one, in practice
            _SCALES[order] = scale
    return scale


def robot_state(ipoc: int, order: tuple[str, ...], v: Array, delay: int | None,
                signals: dict[str, float | dict[str, float]]) -> RobotState:
    """The :class:`RobotState` of checked values.

    Parameters
    ----------
    ipoc : int
        The cycle's stamp.
    order : tuple of str
        The standard elements (``AIPos``, ``RIst`` …) in the packet's order.
    v : ndarray, shape (len(order), 6)
        Their values in robot units (mm, deg, as sent), finite; scaled to SI in place.
    delay : int or None
        ``<Delay D>``.
    signals : dict
        The other elements' values.

    Returns
    -------
    RobotState
        Row ``i`` of ``v · scale`` is the element ``order[i]``.
    """
    v *= scale_of(order)
    values = dict(zip(order, v, strict=True))
    return RobotState(ipoc=ipoc, joints=values.get("AIPos"),
                      joints_setpoint=values.get("ASPos"), tcp=values.get("RIst"),
                      tcp_setpoint=values.get("RSol"), motor_currents=values.get("MACur"),
                      external=values.get("EIPos"), external_setpoint=values.get("ESPos"),
                      delay=delay, signals=signals)


def encode_sen(ipoc: int, kind: str, values: Array, outputs: dict[str, int] | None = None,
               sentype: str = "ImFree") -> bytes:
    """The answer ``<Sen Type=sentype>`` to the packet stamped ``ipoc``.

    Parameters
    ----------
    ipoc : int
        The IPOC of the packet answered, echoed unchanged.
    kind : {"joint", "cartesian"}
        ``AKorr A1..A6`` (values in rad → deg) or ``RKorr X Y Z A B C`` (m → mm,
        rad → deg).
    values : ndarray, shape (6,)
        The correction in SI, already within the link's limits.
    outputs : dict of str to int, optional
        Words routed through RSI (``{"DiO": 5}`` → ``<DiO>5</DiO>``); tags and values are
        the caller's, checked by :class:`~.config.OutputSignal`.
    sentype : str
        ``SENTYPE`` of the ethernet configuration.

    Returns
    -------
    bytes
        The datagram (ASCII).
    """
    form = _SEN_FORMS.get((kind, sentype))
    if form is None:
        form = _sen_form(kind, sentype)
    words = "".join(f"<{k}>{int(w)}</{k}>" for k, w in outputs.items()) if outputs else ""
    return form.format(*(values * _SEN_SCALE[kind]).tolist(), words, int(ipoc)).encode()


#: Robot units per SI unit of each correction's six values (rad → deg; m → mm, rad → deg).
_SEN_SCALE = {"joint": np.full(6, 1.0 / DEG),
              "cartesian": np.array([MM_PER_M] * 3 + [1.0 / DEG] * 3)}
#: The answer's format by (kind, SENTYPE): six values, the output words, the IPOC.
_SEN_FORMS: dict[tuple[str, str], str] = {}


def _sen_form(kind: str, sentype: str) -> str:
    """The format of :func:`encode_sen`'s answer (kept for the next cycle)."""
    tag, axes = ("AKorr", JOINT_AXES) if kind == "joint" else ("RKorr", CARTESIAN_AXES)
    body = " ".join(f'{a}="{{:.6f}}"' for a in axes)
    name = sentype.replace("{", "{{").replace("}", "}}")
    form = f'<Sen Type="{name}"><{tag} {body}/>{{}}<IPOC>{{}}</IPOC></Sen>'
    if len(_SEN_FORMS) < 16:  # a link uses one
        _SEN_FORMS[kind, sentype] = form
    return form


# ------------------------------------------------------------------ the robot's side
# The simulated controller (plugcell.sim.controller.rsi_robot) speaks the other
# direction with the same parser and units: <Rob> out, <Sen> in.


def encode_rob(ipoc: int, joints: Array, tcp: Array, *, joints_setpoint: Array | None = None,
               tcp_setpoint: Array | None = None, delay: int = 0,
               signals: dict[str, float] | None = None) -> bytes:
    """A robot packet ``<Rob Type="KUKA">`` from SI values (what a controller sends).

    Parameters
    ----------
    ipoc : int
        The cycle's stamp.
    joints, joints_setpoint : ndarray, shape (6,)
        ``AIPos``/``ASPos`` (rad → deg); the set-point defaults to ``joints``.
    tcp, tcp_setpoint : ndarray, shape (6,)
        ``RIst``/``RSol``: x, y, z (m → mm), A, B, C (rad → deg).
    delay : int
        ``<Delay D>``: late sensor packets counted so far.
    signals : dict of str to float, optional
        Further elements with a text value (``{"DiL": 5}`` → ``<DiL>5</DiL>``).

    Returns
    -------
    bytes
        The datagram; :func:`parse_rob` reads it back.
    """
    def six(tag: str, axes: tuple[str, ...], v: Array) -> str:
        return f"<{tag} " + " ".join(f'{a}="{x:.4f}"' for a, x in zip(axes, v.tolist(),
                                                                       strict=True)) + "/>"

    def cart(v: Array) -> Array:
        return np.concatenate([np.asarray(v[:3]) * MM_PER_M, np.asarray(v[3:]) * (1.0 / DEG)])

    q = np.asarray(joints, dtype=float) * (1.0 / DEG)
    qs = q if joints_setpoint is None else np.asarray(joints_setpoint, float) * (1.0 / DEG)
    x = cart(np.asarray(tcp, dtype=float))
    xs = x if tcp_setpoint is None else cart(np.asarray(tcp_setpoint, dtype=float))
    extra = "".join(f"<{k}>{v:g}</{k}>" for k, v in (signals or {}).items())
    return (f'<Rob Type="KUKA">{six("RIst", CARTESIAN_AXES, x)}{six("RSol", CARTESIAN_AXES, xs)}'
            f'{six("AIPos", JOINT_AXES, q)}{six("ASPos", JOINT_AXES, qs)}'
            f'<Delay D="{int(delay)}"/>{extra}<IPOC>{int(ipoc)}</IPOC></Rob>').encode()


@dataclass(frozen=True)
class SensorAnswer:
    """One ``<Sen>`` answer, in SI: ``ipoc`` echoed, ``correction`` (6,) — AKorr (rad) or
    RKorr (m, rad) — and the other elements' values (``{"DiO": 5.0}``)."""

    ipoc: int
    correction: Array
    signals: dict[str, float]


def parse_sen(data: bytes, kind: str, max_bytes: int = 4096) -> SensorAnswer:
    """A sensor's answer → :class:`SensorAnswer`, or :class:`PacketError` saying why.

    ``kind`` is the correction the controller's configuration expects: ``"joint"``
    (``AKorr A1..A6``, deg → rad) or ``"cartesian"`` (``RKorr X..C``, mm → m, deg → rad).
    Same parser as :func:`parse_rob` (no DTD, no entities); an answer without the
    correction, with a wrong or non-finite value, or without IPOC is refused.
    """
    if len(data) > max_bytes:
        raise PacketError("oversized", f"{len(data)} bytes > {max_bytes}")
    try:
        root = etree.fromstring(data, _PARSER)
    except etree.XMLSyntaxError as exc:
        raise PacketError("malformed", f"not well-formed XML: {exc}") from None
    if root.tag != "Sen" or root.getroottree().docinfo.doctype:
        raise PacketError("foreign", f"root <{root.tag}>, expected <Sen Type=…>")
    tag, axes = ("AKorr", JOINT_AXES) if kind == "joint" else ("RKorr", CARTESIAN_AXES)
    ipoc: int | None = None
    corr: Array | None = None
    signals: dict[str, float] = {}
    for el in root:
        if type(el.tag) is not str or len(el):
            raise PacketError("malformed", "a sensor packet holds flat elements only")
        if el.tag == "IPOC":
            text = (el.text or "").strip()
            if not text.isdigit() or not text.isascii() or int(text) > IPOC_MAX:
                raise PacketError("malformed", f"<IPOC> {text[:32]!r} is not a counter")
            ipoc = int(text)
        elif el.tag == tag:
            if set(el.keys()) != set(axes):
                raise PacketError("malformed", f"<{tag}> has {sorted(el.keys())}, "
                                  f"expected {list(axes)}")
            corr = np.array([_number(tag, a, el.get(a)) for a in axes])
        elif el.tag in ("AKorr", "RKorr"):
            raise PacketError("foreign", f"<{el.tag}>, the controller expects <{tag}>")
        else:
            signals[el.tag] = _number(el.tag, "text", (el.text or "").strip())
    if ipoc is None:
        raise PacketError("malformed", "no <IPOC>")
    if corr is None:
        raise PacketError("malformed", f"no <{tag}>")
    scale = _JOINT_SCALE if kind == "joint" else _CART_SCALE
    return SensorAnswer(ipoc, corr * scale, signals)
