"""The controller line protocol, version 1 (docs/controller-protocol.md).

The robot service talks to a robot controller — the simulated one, or a real one
whose socket messaging (PDL2, RAPID, KRL) speaks this text — over one TCP
connection: one message per line.  The controller sends the program's
``ACTIVATE DEVICE #Command#Option#Data`` strings (thesis 4.1.3.2), program events
and replies; the service sends the handshake (``ext_cmd_finished`` /
``ext_cmd_result`` and the data variables, 5.2.3.6) and requests (run or stop a
program, ARM_POS, ARM_JNTP, the controller's kinematics, moves).

This module is the message set and its text form: :func:`encode` (message → one
line without the line feed) and :func:`decode` (line → message, or
:class:`ProtocolError` with the precise reason — never another exception).
Framing (bytes → lines) is in :mod:`plugcell.devices.robot.framing`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

from plugcell.devices.robot.activate import (
    KEYWORD,
    ActivateString,
    ActivateSyntaxError,
    format_activate,
    parse_activate,
)

__all__ = [
    "MAX_ID",
    "PROGRAM_STATES",
    "PROTOCOL",
    "REQUESTS",
    "VERSION",
    "ActivateLine",
    "ArmJntp",
    "ArmPos",
    "Console",
    "Hello",
    "JntpToPos",
    "Message",
    "Move",
    "Ping",
    "PosToJntp",
    "ProgramEnded",
    "ProgramStarted",
    "ProtocolError",
    "Reply",
    "Request",
    "Result",
    "ResultData",
    "Run",
    "Status",
    "Stop",
    "StreamEnd",
    "Value",
    "decode",
    "encode",
    "escape",
    "format_numbers",
    "parse_fields",
    "parse_numbers",
    "unescape",
]

PROTOCOL = "plugcell-controller"
VERSION = 1
#: Request identifiers are 1 … MAX_ID (0 in an ERR reply means "no request could be read").
MAX_ID = 2**31 - 1
#: How a program run ends (``EVENT ENDED``), plus RUNNING in status replies.
PROGRAM_STATES = ("FINISHED", "DEACTIVATED", "FAILED", "STOPPED")

Sender = Literal["controller", "service"]


class ProtocolError(ValueError):
    """A line that is not a valid message; the text says exactly why."""


# ----------------------------------------------------------------------------- text fields
_ESCAPES = {"\\": "\\\\", "\n": "\\n", "\r": "\\r", "\t": "\\t"}
_UNESCAPES = {"\\": "\\", "n": "\n", "r": "\r", "t": "\t"}


def escape(text: str) -> str:
    """A free-text field on one line: ``\\`` ``LF`` ``CR`` ``TAB`` and other control
    characters as ``\\\\ \\n \\r \\t \\xHH``."""
    out = []
    for ch in text:
        if ch in _ESCAPES:
            out.append(_ESCAPES[ch])
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\x{ord(ch):02x}")
        else:
            out.append(ch)
    return "".join(out)


def unescape(text: str) -> str:
    """Inverse of :func:`escape`; ProtocolError for a bad escape or a raw control character."""
    out = []
    i = 0
    while i < len(text):
        ch = text[i]
        if ch == "\\":
            nxt = text[i + 1 : i + 2]
            if nxt in _UNESCAPES:
                out.append(_UNESCAPES[nxt])
                i += 2
                continue
            if nxt == "x" and re.fullmatch(r"[0-9a-fA-F]{2}", text[i + 2 : i + 4]):
                out.append(chr(int(text[i + 2 : i + 4], 16)))
                i += 4
                continue
            raise ProtocolError(f"bad escape {text[i : i + 2]!r} at column {i + 1}")
        if (ord(ch) < 0x20 and ch != "\t") or ord(ch) == 0x7F:
            raise ProtocolError(f"raw control character U+{ord(ch):04X} at column {i + 1}")
        out.append(ch)
        i += 1
    return "".join(out)


_NUMBER = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?\Z")


def format_number(x: float) -> str:
    """Shortest text that reads back to the same double (integers without a point)."""
    if isinstance(x, bool):
        return "1" if x else "0"
    if isinstance(x, int):
        return str(x)
    v = float(x)
    if not math.isfinite(v):
        raise ValueError(f"{v} cannot be sent: only finite numbers")
    return repr(v)


def format_numbers(values: Sequence[float]) -> str:
    """``1.5,2,3`` — comma-separated, no blanks (empty for no values)."""
    return ",".join(format_number(v) for v in values)


def parse_number(token: str) -> float:
    """A decimal number (no NaN, no infinity, no ``_``); ProtocolError otherwise."""
    if not _NUMBER.match(token):
        raise ProtocolError(f"{token[:40]!r} is not a number")
    value = float(token)
    if not math.isfinite(value):
        raise ProtocolError(f"{token[:40]!r} is out of range")
    return value


def parse_numbers(text: str, count: int | None = None, what: str = "values") -> tuple[float, ...]:
    """``1.5,2,3`` → floats; exactly ``count`` of them if given."""
    values = () if text == "" else tuple(parse_number(t) for t in text.split(","))
    if count is not None and len(values) != count:
        raise ProtocolError(f"{what}: expected {count} numbers, got {len(values)}")
    return values


def _parse_id(token: str) -> int:
    if not re.fullmatch(r"\d{1,10}", token) or not 1 <= int(token) <= MAX_ID:
        raise ProtocolError(f"bad request id {token[:20]!r}: an integer 1…{MAX_ID}")
    return int(token)


def _parse_count(token: str, what: str) -> int:
    if not re.fullmatch(r"\d{1,9}", token):
        raise ProtocolError(f"bad {what} {token[:20]!r}: a non-negative integer")
    return int(token)


def _bool(token: str) -> bool:
    if token == "TRUE":
        return True
    if token == "FALSE":
        return False
    raise ProtocolError(f"expected TRUE or FALSE, found {token[:20]!r}")


def _token(value: str, what: str) -> str:
    if not value or any(c in value for c in " \t\r\n") or ("=" in value and what == "key"):
        raise ValueError(f"{what} {value!r} must be a non-empty word without blanks")
    return value


def parse_fields(tokens: Sequence[str]) -> dict[str, str]:
    """``key=value`` words (HELLO, status replies) → a dict; values may be empty."""
    out: dict[str, str] = {}
    for t in tokens:
        key, sep, value = t.partition("=")
        if not sep or not key:
            raise ProtocolError(f"expected key=value, found {t[:40]!r}")
        out[key] = value
    return out


def format_fields(fields: dict[str, str]) -> str:
    return " ".join(f"{_token(k, 'key')}={_token(v, 'value') if v else ''}"
                    for k, v in fields.items())


# ----------------------------------------------------------------------------- messages
@dataclass(frozen=True)
class Hello:
    """C→S, the first line: who the controller is (``robot=``, ``axes=``, capacities…)."""

    version: int = VERSION
    fields: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class ActivateLine:
    """C→S: a program's request, exactly as the program wrote it (4.1.3.2)."""

    activate: ActivateString


@dataclass(frozen=True)
class ProgramStarted:
    """C→S ``EVENT STARTED <run> <program>``: run ``run`` (the RUN id, 0 if started
    at the controller) began; every ACTIVATE line until its ENDED belongs to it."""

    run: int
    program: str


@dataclass(frozen=True)
class ProgramEnded:
    """C→S ``EVENT ENDED``: how the run ended, its simulated and real seconds, why."""

    run: int
    program: str
    state: str
    sim_time: float
    real_time: float
    message: str = ""


@dataclass(frozen=True)
class Console:
    """C→S ``EVENT CONSOLE <run> <text>``: a line the program wrote to LUN_CRT."""

    run: int
    text: str


@dataclass(frozen=True)
class Reply:
    """C→S ``OK <id> [text]`` / ``ERR <id> <text>``: the answer to request ``id``."""

    id: int
    ok: bool
    text: str = ""


@dataclass(frozen=True)
class Result:
    """S→C ``RESULT TRUE|FALSE [message]``: the handshake — ext_cmd_message, then
    ext_cmd_result, then ``ext_cmd_finished := TRUE``, together with the
    ResultData sent just before it (one batch)."""

    ok: bool
    message: str = ""


@dataclass(frozen=True)
class ResultData:
    """S→C ``DATA <rows> <cols> <v,...>`` or ``TEXT <text>``: data of the next RESULT
    (``frame=True``: ``FRAME``/``FRAMETEXT``, one item of a MultipleData stream,
    applied at once without the handshake)."""

    rows: int = 0
    cols: int = 0
    values: tuple[float, ...] = ()
    text: str | None = None
    frame: bool = False


@dataclass(frozen=True)
class StreamEnd:
    """S→C ``STREAMEND TRUE|FALSE [message]``: a stream ended on its own (FALSE:
    ``ext_cmd_result := FALSE`` and ``ext_cmd_message``, no handshake)."""

    ok: bool
    message: str = ""


@dataclass(frozen=True)
class Request:
    """Base of the service's requests; ``id`` is echoed by the Reply."""

    id: int


@dataclass(frozen=True)
class Ping(Request):
    """``PING <id>`` → ``OK <id>``."""


@dataclass(frozen=True)
class Status(Request):
    """``STATUS <id>`` → ``OK <id> state=… run=… program=… sim=… clock=… line=…``."""


@dataclass(frozen=True)
class Value(Request):
    """``VALUE <id> <name> <text>``: a preset of the RUN with the same id (PDL's
    variable file); answered by that RUN."""

    name: str = ""
    text: str = ""


@dataclass(frozen=True)
class Run(Request):
    """``RUN <id> <program>``: load (by library name or path) and start a program."""

    program: str = ""


@dataclass(frozen=True)
class Stop(Request):
    """``STOP <id> [<program>]``: stop the running program (if it is ``program``)."""

    program: str = ""


@dataclass(frozen=True)
class ArmPos(Request):
    """``ARM_POS <id>`` → ``OK <id> x,y,z,a,b,c`` (mm, Comau ZYZ degrees)."""


@dataclass(frozen=True)
class ArmJntp(Request):
    """``ARM_JNTP <id>`` → ``OK <id> q1,…,qn`` (degrees)."""


@dataclass(frozen=True)
class PosToJntp(Request):
    """``POS_TO_JNTP <id> x,y,z,a,b,c`` → joints: the controller's inverse kinematics."""

    values: tuple[float, ...] = ()


@dataclass(frozen=True)
class JntpToPos(Request):
    """``JNTP_TO_POS <id> q1,…,qn`` → pose: the controller's forward kinematics."""

    values: tuple[float, ...] = ()


@dataclass(frozen=True)
class Move(Request):
    """``MOVE <id> JOINT q1,…,qn`` / ``MOVE <id> TO x,y,z,a,b,c`` → ``OK <id> <seconds>``
    (simulated duration) once the arm is there."""

    kind: str = "JOINT"
    values: tuple[float, ...] = ()


Message = (
    Hello | ActivateLine | ProgramStarted | ProgramEnded | Console | Reply
    | Result | ResultData | StreamEnd | Request
)

#: Request verbs → classes (S→C).
REQUESTS: dict[str, type[Request]] = {
    "PING": Ping,
    "STATUS": Status,
    "VALUE": Value,
    "RUN": Run,
    "STOP": Stop,
    "ARM_POS": ArmPos,
    "ARM_JNTP": ArmJntp,
    "POS_TO_JNTP": PosToJntp,
    "JNTP_TO_POS": JntpToPos,
    "MOVE": Move,
}
_VERB_OF = {cls: verb for verb, cls in REQUESTS.items()}
_NAME = re.compile(r"[A-Za-z_$][A-Za-z0-9_$]{0,63}\Z")


def _with_text(head: str, text: str) -> str:
    return f"{head} {escape(text)}" if text else head


# ----------------------------------------------------------------------------- encode
def encode(message: Message) -> str:
    """The line of ``message`` (no line feed).  ValueError for a message that cannot
    be written (a name with blanks, a non-finite number…)."""
    m = message
    if isinstance(m, Hello):
        fields = format_fields(m.fields)
        return f"HELLO {PROTOCOL} {m.version}" + (f" {fields}" if fields else "")
    if isinstance(m, ActivateLine):
        return format_activate(m.activate)
    if isinstance(m, ProgramStarted):
        return f"EVENT STARTED {m.run} {_token(m.program, 'program')}"
    if isinstance(m, ProgramEnded):
        if m.state not in PROGRAM_STATES:
            raise ValueError(f"state {m.state!r} is not one of {PROGRAM_STATES}")
        head = (f"EVENT ENDED {m.run} {_token(m.program, 'program')} {m.state} "
                f"{format_number(float(m.sim_time))} {format_number(float(m.real_time))}")
        return _with_text(head, m.message)
    if isinstance(m, Console):
        return f"EVENT CONSOLE {m.run} {escape(m.text)}"
    if isinstance(m, Reply):
        if m.ok:
            return _with_text(f"OK {m.id}", m.text)
        return f"ERR {m.id} {escape(m.text or 'error')}"
    if isinstance(m, Result):
        return _with_text(f"RESULT {'TRUE' if m.ok else 'FALSE'}", m.message)
    if isinstance(m, StreamEnd):
        return _with_text(f"STREAMEND {'TRUE' if m.ok else 'FALSE'}", m.message)
    if isinstance(m, ResultData):
        if m.text is not None:
            return _with_text("FRAMETEXT" if m.frame else "TEXT", m.text)
        if m.rows * m.cols != len(m.values):
            raise ValueError(f"{m.rows} x {m.cols} does not match {len(m.values)} values")
        verb = "FRAME" if m.frame else "DATA"
        return f"{verb} {m.rows} {m.cols} {format_numbers(m.values)}".rstrip(" ")
    if isinstance(m, Request):
        verb = _VERB_OF[type(m)]
        if not 1 <= m.id <= MAX_ID:
            raise ValueError(f"request id {m.id} outside 1…{MAX_ID}")
        head = f"{verb} {m.id}"
        if isinstance(m, Value):
            if not _NAME.match(m.name):
                raise ValueError(f"bad variable name {m.name!r}")
            return _with_text(f"{head} {m.name}", m.text)
        if isinstance(m, Run):
            if not m.program:
                raise ValueError("RUN needs a program")
            return f"{head} {escape(m.program)}"
        if isinstance(m, Stop):
            return _with_text(head, m.program)
        if isinstance(m, PosToJntp | JntpToPos):
            return f"{head} {format_numbers(m.values)}"
        if isinstance(m, Move):
            if m.kind not in ("JOINT", "TO"):
                raise ValueError(f"MOVE kind must be JOINT or TO, not {m.kind!r}")
            return f"{head} {m.kind} {format_numbers(m.values)}"
        return head
    raise TypeError(f"not a protocol message: {type(message).__name__}")


# ----------------------------------------------------------------------------- decode
_FROM_CONTROLLER = ("HELLO", "EVENT", "OK", "ERR", KEYWORD)
_FROM_SERVICE = ("RESULT", "DATA", "TEXT", "FRAME", "FRAMETEXT", "STREAMEND", *REQUESTS)


def decode(line: str, sender: Sender) -> Message:
    """Read one line sent by ``sender`` (``"controller"`` or ``"service"``).

    Raises :class:`ProtocolError` with the reason for anything that is not a
    valid message of that sender; never raises anything else.
    """
    try:
        return _decode(line, sender)
    except ProtocolError:
        raise
    except ActivateSyntaxError as exc:
        raise ProtocolError(f"bad ACTIVATE string: {exc}") from None
    except (ValueError, TypeError, IndexError, OverflowError) as exc:  # pragma: no cover
        raise ProtocolError(f"unreadable line: {exc}") from None


def _split(line: str, n: int) -> list[str]:
    """The first ``n`` words and the rest (one blank separates words)."""
    parts = line.split(" ", n)
    return parts + [""] * (n + 1 - len(parts))


def _decode(line: str, sender: Sender) -> Message:
    if not isinstance(line, str):
        raise ProtocolError(f"expected text, got {type(line).__name__}")
    line = line.rstrip("\r")
    if not line.strip():
        raise ProtocolError("empty line")
    verb = line.split(" ", 1)[0]
    if sender == "controller" and verb.upper() == KEYWORD:
        return ActivateLine(parse_activate(line))
    allowed = _FROM_CONTROLLER if sender == "controller" else _FROM_SERVICE
    if verb not in allowed:
        other = _FROM_SERVICE if sender == "controller" else _FROM_CONTROLLER
        if verb in other:
            raise ProtocolError(f"{verb} is not a message the {sender} sends")
        raise ProtocolError(
            f"unknown message {verb[:40]!r} (a {sender} sends "
            f"{', '.join(v for v in allowed)})"
        )
    if sender == "controller":
        return _decode_from_controller(verb, line)
    return _decode_from_service(verb, line)


def _decode_from_controller(verb: str, line: str) -> Message:
    if verb == "HELLO":
        words = line.split(" ")
        if len(words) < 3 or words[1] != PROTOCOL:
            raise ProtocolError(f"expected HELLO {PROTOCOL} <version> [key=value …]")
        if not re.fullmatch(r"\d{1,4}", words[2]):
            raise ProtocolError(f"bad protocol version {words[2][:20]!r}")
        return Hello(int(words[2]), parse_fields([w for w in words[3:] if w]))
    if verb == "EVENT":
        _, kind, run, rest = _split(line, 3)
        run_id = _parse_count(run, "run id")
        if kind == "STARTED":
            if not rest or " " in rest:
                raise ProtocolError("expected EVENT STARTED <run> <program>")
            return ProgramStarted(run_id, rest)
        if kind == "CONSOLE":
            return Console(run_id, unescape(rest))
        if kind == "ENDED":
            program, state, sim, real, text = _split(rest, 4)
            if not program:
                raise ProtocolError("expected EVENT ENDED <run> <program> <state> <sim> <real>")
            if state not in PROGRAM_STATES:
                raise ProtocolError(f"bad program state {state[:20]!r} (one of "
                                    f"{', '.join(PROGRAM_STATES)})")
            return ProgramEnded(run_id, program, state, parse_number(sim), parse_number(real),
                                unescape(text))
        raise ProtocolError(f"unknown event {kind[:20]!r} (STARTED, ENDED, CONSOLE)")
    # OK / ERR
    _, ident, text = _split(line, 2)
    if verb == "ERR" and ident == "0":
        return Reply(0, False, unescape(text))
    reply_id = _parse_id(ident)
    if verb == "ERR" and not text:
        raise ProtocolError(f"ERR {reply_id} without a reason")
    return Reply(reply_id, verb == "OK", unescape(text))


def _decode_from_service(verb: str, line: str) -> Message:
    if verb in ("RESULT", "STREAMEND"):
        _, flag, text = _split(line, 2)
        cls = Result if verb == "RESULT" else StreamEnd
        return cls(_bool(flag), unescape(text))
    if verb in ("TEXT", "FRAMETEXT"):
        return ResultData(text=unescape(_split(line, 1)[1]), frame=verb == "FRAMETEXT")
    if verb in ("DATA", "FRAME"):
        _, rows, cols, values = _split(line, 3)
        r, c = _parse_count(rows, "row count"), _parse_count(cols, "column count")
        numbers = parse_numbers(values, r * c, f"{verb} {r} {c}")
        return ResultData(r, c, numbers, frame=verb == "FRAME")
    cls = REQUESTS[verb]
    _, ident, rest = _split(line, 2)
    rid = _parse_id(ident)
    if cls is Value:
        name, text = _split(rest, 1)
        if not _NAME.match(name):
            raise ProtocolError(f"bad variable name {name[:40]!r}")
        return Value(rid, name, unescape(text))
    if cls is Run:
        if not rest:
            raise ProtocolError("RUN needs a program name or path")
        return Run(rid, unescape(rest))
    if cls is Stop:
        return Stop(rid, unescape(rest))
    if cls is PosToJntp:
        return PosToJntp(rid, parse_numbers(rest, 6, "POS_TO_JNTP"))
    if cls is JntpToPos:
        values = parse_numbers(rest, None, "JNTP_TO_POS")
        if not 1 <= len(values) <= 10:
            raise ProtocolError(f"JNTP_TO_POS: expected 1…10 joint angles, got {len(values)}")
        return JntpToPos(rid, values)
    if cls is Move:
        kind, values = _split(rest, 1)
        if kind == "TO":
            return Move(rid, "TO", parse_numbers(values, 6, "MOVE TO"))
        if kind == "JOINT":
            numbers = parse_numbers(values, None, "MOVE JOINT")
            if not 1 <= len(numbers) <= 10:
                raise ProtocolError(f"MOVE JOINT: expected 1…10 joint angles, got {len(numbers)}")
            return Move(rid, "JOINT", numbers)
        raise ProtocolError(f"expected MOVE <id> JOINT|TO <values>, found {kind[:20]!r}")
    if rest:
        raise ProtocolError(f"{verb} takes no arguments, found {rest[:40]!r}")
    return cls(rid)
