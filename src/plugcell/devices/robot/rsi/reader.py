"""Reading the robot's packets in the cycle: the layout the controller repeats, as one pattern.

A controller sends the same elements in the same order every cycle (its ethernet
configuration's ``SEND`` list); only the numbers change.  :class:`RobReader` reads a
packet with :func:`.codec.parse_rob` (lxml and every check) and learns its *layout* —
the tags in order, each one's attributes in order or its text — as one compiled regular
expression.  A later packet that the pattern matches whole is read from the pattern's
groups into the same :class:`~.codec.RobotState`, at a fraction of lxml's cost (the
numbers: ``benchmarks/stream_cycle_profile.py``).  Anything else — another layout, a
value the pattern does not take, a number that is not finite, a counter out of range —
goes to ``parse_rob``: its result or its :class:`~..stream.errors.PacketError`, exactly
as without the reader, and a layout read so is learnt in turn.

Why a match reads as lxml would: the pattern is the learnt packet's markup with white
space (``[ \\t\\r\\n]``) allowed where XML ignores it — around the root, between elements, between
attributes, around ``=`` and before ``/>`` — and each value limited to printable ASCII
without ``<``, ``&`` (and ``"`` in attributes): no entity, no character reference, no
CDATA, no comment, none of the white space XML normalizes in values, so lxml would give
exactly these characters.  Such a packet is well-formed, has the learnt packet's
elements (which passed every check of ``parse_rob``), and each value gets the check
``parse_rob`` gives it: numbers must convert with ``float`` and be finite, the IPOC is
ASCII digits within :data:`.codec.IPOC_MAX`, ``<Delay D>`` a count.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from operator import itemgetter

import numpy as np
from lxml import etree

from .codec import (
    _STANDARD,
    DELAY_MAX,
    IPOC_MAX,
    RobotState,
    read_rob,
    rob_root,
    robot_state,
)

__all__ = ["RobReader"]

_WS = r"[ \t\r\n]"
#: An attribute's value: printable ASCII but ``"``, ``&``, ``<``.
_ATTR = r"""([ !#-%'-;=-~]*)"""
#: An element's text: printable ASCII but ``&``, ``<``.
_TEXT = r"([ -%'-;=-~]*)"


@dataclass(frozen=True)
class _Layout:
    """One learnt layout: the pattern and where each value is among its groups.

    Attributes
    ----------
    pattern : re.Pattern
        The whole packet, one group per value, in the packet's order.
    order : tuple of str
        The standard elements (``AIPos`` …) in the packet's order.
    numbers : callable
        The groups' tuple → the numbers' texts: the standard elements' six values each
        (axis order), then ``<Delay D>`` (if sent), then every signal's values.
    ipoc : int
        The group of the IPOC.
    delay : bool
        The packet has ``<Delay D>``.
    signals : tuple of (str, tuple of str or None)
        Each signal element's tag and its attributes (``None``: its text), in order.
    """

    pattern: re.Pattern[str]
    order: tuple[str, ...]
    numbers: Callable[[tuple[str, ...]], tuple[str, ...]]
    ipoc: int
    delay: bool
    signals: tuple[tuple[str, tuple[str, ...] | None], ...]

    def read(self, text: str) -> RobotState | None:
        """The state of a packet of this layout; ``None`` for anything else."""
        m = self.pattern.fullmatch(text)
        if m is None:
            return None
        groups = m.groups()
        try:
            numbers = [float(x) for x in self.numbers(groups)]
        except ValueError:
            return None
        # one sum tells finite from not (a sum of finite values that overflows only
        # sends a good packet the slow way)
        if not math.isfinite(sum(numbers)):
            return None
        ipoc = int(groups[self.ipoc])
        if ipoc > IPOC_MAX:
            return None
        n = 6 * len(self.order)
        delay = None
        if self.delay:
            d = numbers[n]
            if not 0 <= d <= DELAY_MAX or d != int(d):
                return None
            delay = int(d)
            n += 1
        signals: dict[str, float | dict[str, float]] = {}
        for tag, names in self.signals:
            if names is None:
                signals[tag] = numbers[n]
                n += 1
            else:
                signals[tag] = dict(zip(names, numbers[n:n + len(names)], strict=True))
                n += len(names)
        v = np.array(numbers[:6 * len(self.order)]).reshape(len(self.order), 6)
        return robot_state(ipoc, self.order, v, delay, signals)


def _picker(indices: Sequence[int]) -> Callable[[tuple[str, ...]], tuple[str, ...]]:
    """``groups → tuple(groups[i] for i in indices)``, in C where it can be."""
    if len(indices) >= 2:
        return itemgetter(*indices)
    return lambda groups: tuple(groups[i] for i in indices)


def _learn(root: etree._Element) -> _Layout:
    """The layout of a packet that :func:`.codec.read_rob` has read."""
    parts = [_WS + '*<Rob Type="KUKA">']
    group = 0
    order: list[str] = []
    standard: list[int] = []
    delay: list[int] = []
    signal_groups: list[int] = []
    signals: list[tuple[str, tuple[str, ...] | None]] = []
    ipoc = -1
    for el in root:
        tag, names = el.tag, tuple(el.keys())
        parts.append(_WS + "*<" + re.escape(tag))
        if tag == "IPOC":
            parts.append(">([0-9]+)</IPOC>")
            ipoc = group
            group += 1
            continue
        if not names:
            parts.append(">" + _TEXT + "</" + re.escape(tag) + ">")
            signals.append((tag, None))
            signal_groups.append(group)
            group += 1
            continue
        first = {name: group + i for i, name in enumerate(names)}
        parts += [f"{_WS}+{re.escape(name)}{_WS}*={_WS}*\"{_ATTR}\"" for name in names]
        parts.append(_WS + "*/>")
        group += len(names)
        if tag in _STANDARD:
            order.append(tag)
            standard += [first[a] for a in _STANDARD[tag][0]]
        elif tag == "Delay":
            delay.append(first["D"])
        else:
            signals.append((tag, names))
            signal_groups += list(first.values())
    parts.append(_WS + "*</Rob>" + _WS + "*")
    return _Layout(re.compile("".join(parts)), tuple(order),
                   _picker(standard + delay + signal_groups), ipoc, bool(delay),
                   tuple(signals))


class RobReader:
    """:func:`.codec.parse_rob` with a fast path for the layout the controller repeats
    (module doc); one per link (it keeps the layout last learnt).

    Parameters
    ----------
    max_bytes : int
        Larger datagrams are ``oversized``, as for ``parse_rob``.
    """

    def __init__(self, max_bytes: int = 4096) -> None:
        self.max_bytes = max_bytes
        self._layout: _Layout | None = None
        #: Packets read by the pattern, and by ``parse_rob`` (the counters of the fast path).
        self.fast = self.slow = 0

    def __call__(self, data: bytes) -> RobotState:
        """One datagram → :class:`~.codec.RobotState` (SI), or ``PacketError`` saying why:
        what :func:`.codec.parse_rob` gives.

        Parameters
        ----------
        data : bytes
            The datagram as received.

        Returns
        -------
        RobotState
            The packet's values in SI.
        """
        layout = self._layout
        if layout is not None and len(data) <= self.max_bytes and data.isascii():
            state = layout.read(data.decode("ascii"))
            if state is not None:
                self.fast += 1
                return state
        root = rob_root(data, self.max_bytes)
        state = read_rob(root)  # raises for what is no robot packet: nothing learnt
        self.slow += 1
        if len(root.attrib) == 1:  # the pattern's root is <Rob Type="KUKA"> alone
            self._layout = _learn(root)
        return state
