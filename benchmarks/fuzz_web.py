"""Fuzz the web API of the cell controller UI (issue 10 §4):
``python benchmarks/fuzz_web.py [--cases N] [--seed S] [--hang-s T]`` (default 100 000 cases).

Every HTTP route of :func:`plugcell.apps.ui.app.create_app` — found by walking
``app.routes``, not listed here; the static mount counts as one route, the websocket
is left out — gets an equal share of the cases, sent in-process through httpx's ASGI
transport (as uvicorn would pass them, on port 8765) to the app on a real
:class:`~plugcell.devices.cell.service.CellController` in a fresh cell, with an
in-process drill service (``TOOL``, time scale 0.001) so tasks reach a real catalogue.
Zenoh runs in-process; no child process is started.  ``fuzz_web()`` is what
``tests/ui/test_ui_fuzz_web.py`` runs with a few thousand cases.

Inputs (seeded): mutations of a valid body of the route (a node replaced by a value
of another type, a huge or non-finite number, an over-long or odd Unicode string, a
deeply nested list, keys dropped or unknown keys added) and of its path parameters;
then, now and then, the bytes garbled (truncated, flipped, invalid UTF-8, nested
100 000 deep, a 5 000-digit number, ``NaN``, a lone surrogate, over the size limit),
a wrong ``Content-Type``, a foreign ``Host``/``Origin``, a missing ``X-Plugcell``
header, a junk query string or the wrong method.

Judged: no 5xx (an exception escaping the app counts as a 500 — a crash); every
4xx, and every ``200`` with ``ok: false``, is JSON with a non-generic message:
``{"ok": false, "errors": {field: why}}`` from the app, or Starlette's
``{"detail": why}`` for a route or method that does not exist.  The slowest case of
each route is reported (speed is measured, not asserted); a case unanswered after
``--hang-s`` seconds is cancelled and fails, one that cannot be cancelled ends the run
with its input after twice as long (exit 3).  Exit 1 if any case failed.

String values in generated bodies never contain ``/`` or ``\\``: the wiring file
endpoints write where they are told, so the run stays in its scratch directory (the
current directory during the run).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import logging
import math
import os
import random
import sys
import tempfile
import threading
import time
import uuid
import warnings
from collections import Counter
from collections.abc import AsyncIterator, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import quote

import httpx2 as httpx  # the HTTP client of the dev dependencies (Starlette's TestClient uses it)
from starlette.routing import Mount, Route

from plugcell.apps.ui.app import create_app
from plugcell.apps.ui.guard import MAX_BODY
from plugcell.apps.ui.reports import ReportFiles
from plugcell.devices.cell.service import cell_controller
from plugcell.devices.drill import DrillService
from plugcell.framework import GenericDevice
from plugcell.sim.drivers.drill import SimulatedDrill

HEADERS = {"X-Plugcell": "1", "Content-Type": "application/json"}
#: With a port, as uvicorn serves it (the ASGI scope's port is None without one, and
#: Starlette's slash redirect then writes ``:None`` into the Location header).
BASE_URL = "http://127.0.0.1:8765"
#: Messages too vague to tell anyone what to fix.
GENERIC = {"", "error", "failed", "internal server error", "bad request", "invalid"}


def _circle(n: int = 12, r: float = 100.0) -> list[list[float]]:
    return [[1000 + r * math.cos(2 * math.pi * i / n), 200 + r * math.sin(2 * math.pi * i / n),
             500.0] for i in range(n)]


#: Valid bodies to mutate, by route (a route without one gets ``{}``).
BODIES: dict[str, list[Any]] = {
    "/api/wire": [{"service": "TOOL", "partner": "CONTROLLER"}],
    "/api/unwire": [{"service": "TOOL", "partner": "CONTROLLER"}],
    "/api/tasks": [
        {"service": "TOOL", "command": "Drill", "option": "Air", "data": [550, 1100],
         "timeout": 30},
        {"service": "CONTROLLER", "command": "Cell", "option": "", "data": None},
    ],
    "/api/tasks/stop": [{"id": "TOOL/CONTROLLER/1"}],
    "/api/runs": [{"items": [{"robot": "R1", "program": "example"}], "mode": "sequential"},
                  {"items": ["R1:example", ["R2", "calibration"]], "mode": "concurrent"}],
    "/api/wiring/save": [{"path": "fuzz-wiring.json"}],
    "/api/wiring/load": [
        {"path": "fuzz-wiring.json"},
        {"document": {"format": "plugcell-cell-wiring", "version": 1, "cell": "lab",
                      "wires": [{"service": "TOOL", "partner": "CONTROLLER"}]}},
    ],
    "/api/fit": [{"kind": "circle", "points": _circle()},
                 {"kind": "line", "points": [[0, 0, 0], [100, 1, 0], [200, 0, 1]]},
                 {"kind": "plane", "points": [[0, 0, 0], [500, 0, 0], [0, 500, 0],
                                              [400, 400, 1]]}],
    "/api/wizard/{which}": [
        {"circle": _circle(), "holes": [[1000, 150, 500], [1000, 250, 500]],
         "tmac": [1000, 200, 600, 0, 0, 0], "smr_offset": 0},
        {"circle": _circle(r=300), "plane": [[0, 0, 0], [500, 0, 0], [0, 500, 0], [400, 400, 0]],
         "line": [[0, 0, 900], [100, 0, 900]], "smr_offset": 6.35,
         "tmac": [[1, 0, 0, 10], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]},
    ],
}
BODIES["/api/tasks/check"] = BODIES["/api/tasks"]
BODIES["/api/residuals"] = [
    {"matrix": [[1000, 0, 500, 0.1, -0.2, 0.05], [1100, 50, 520, 0.0, 0.1, -0.1]]},
    {"document": {"format": "plugcell-residuals", "format_version": 1, "robot": "ur10",
                  "model": {"number": 3, "name": "kinematic"},
                  "poses": [{"set": "calibration", "index": 1, "measured_mm": [1000, 0, 500],
                             "after_mm": [0.1, 0, 0], "before_mm": [1.5, -2, 0.3]},
                            {"set": "validation", "index": 2, "measured_mm": [900, 10, 450],
                             "after_mm": [0, 0.2, 0], "before_mm": [2, 1, 0]}]}},
    {"service": "TOOL", "name": "res", "workspace": "R1"},
]
BODIES["/api/matrix"] = [{"service": "TOOL", "name": "mT", "workspace": "H4"}]
BODIES["/api/wizard/live"] = [
    {"robot": "R1", "tracker": "TRACKER", "compute": "COMPUTE", "reflectors": [[0, 0, 100]],
     "base_est": [1000, 0, 0, 0, 0, 0], "duration_ms": 100, "matrix": "pts", "timeout": 60,
     "joints": [0, -90, 90, 0, 0, 0], "sweep": {"joint": 1, "from": -30, "to": 30, "count": 5}},
    {"robot": "R1", "reflectors": [[0, 0, 100, 0, 0, 0]], "base_est": [0, 0, 0, 0, 0, 0],
     "line": {"axis": "x", "length": 200, "count": 3}},
]
#: Values of path parameters to mutate, by parameter name (else a few words).
PARAMS: dict[str, list[str]] = {
    "which": ["probe", "base"],
    "name": ["example", "calibration", "8.1.md", "fig.png"],
    "index": ["0", "1", "-1"],
    "path": ["index.html", "favicon.svg", "js/main.js", "css/main.css"],
}
ALPHABET = ("abcXYZ019_-.:,;# \t\n\"'{}[]=+*?%&~é€ÿ\x00\x1f\x7f\u200b\u202e\ufeff𝔘😀"
            "\ud800\udfff")
ODD_STRINGS = ["", " ", "NaN", "Infinity", "-inf", "1e999", "0x10", "true", "null", "∕etc∕passwd",
               "..", ".", "~", "CON", "\x00", "\ud800", "\udc00x", "😀" * 50, "\u202e\u2066",
               "a" * 300, "é" * 5000, "TOOL", "CONTROLLER", "Drill", "Air", "circle"]
ODD_NUMBERS: list[Any] = [0, -1, 1, 2**31, -2**63, 2**64, 10**30, -10**300, 10**400, -10**4000,
                          1e308, -1e308,
                          5e-324, -0.0, 1.5, 1e-9, math.nan, math.inf, -math.inf, 604801,
                          True, False]


def _strings(value: Any) -> Iterator[tuple[Any, Any, str]]:
    """(container, key, text) of every string under ``value``, keys as ``(node, None, key)``."""
    stack = [value]
    while stack:  # iterative: the value may be nested deeper than the recursion limit
        node = stack.pop()
        pairs = list(node.items()) if isinstance(node, dict) else list(enumerate(node)) \
            if isinstance(node, list) else []
        for key, item in pairs:
            if isinstance(node, dict):
                yield node, None, key
            if isinstance(item, str):
                yield node, key, item
            else:
                stack.append(item)


def _slashed(text: str) -> bool:
    return "/" in text or "\\" in text


def _tame(value: Any) -> Any:
    """``value`` with ``/`` and ``\\`` out of every string (no file outside the scratch dir)."""
    def fix(text: str) -> str:
        return text.replace("/", "∕").replace("\\", "⧵")

    if isinstance(value, str):
        return fix(value)
    found = [(node, key, text) for node, key, text in _strings(value) if _slashed(text)]
    for node, key, text in found:  # values first, then the keys holding them
        if key is not None:
            node[key] = fix(text)
    for node, key, text in found:
        if key is None:
            node[fix(text)] = node.pop(text)
    return value


def _string(rng: random.Random) -> str:
    r = rng.random()
    if r < 0.35:
        return rng.choice(ODD_STRINGS)
    if r < 0.5:
        return "".join(chr(rng.randrange(0, 0x11000)) for _ in range(rng.randrange(0, 30)))
    if r < 0.53:
        return rng.choice(ALPHABET) * rng.choice((1_000, 70_000))
    return "".join(rng.choice(ALPHABET) for _ in range(rng.randrange(0, 24)))


def random_value(rng: random.Random, depth: int = 0) -> Any:
    """A JSON value of any type (Python's json writes NaN and Infinity as some clients do)."""
    r = rng.random()
    if depth > 3 or r < 0.3:
        return rng.choice(ODD_NUMBERS) if rng.random() < 0.6 else rng.uniform(-1e6, 1e6)
    if r < 0.55:
        return _string(rng)
    if r < 0.6:
        return None
    if r < 0.8:
        if rng.random() < 0.02:
            short = [v for v in ODD_NUMBERS if not isinstance(v, int) or abs(v) <= 2**64]
            return [rng.choice(short)] * rng.choice((10_000, 200_000))
        return [random_value(rng, depth + 1) for _ in range(rng.randrange(0, 6))]
    return {_string(rng) if rng.random() < 0.3 else rng.choice(("kind", "points", "x", "_")):
            random_value(rng, depth + 1) for _ in range(rng.randrange(0, 4))}


def _nest(value: Any, depth: int) -> Any:
    for _ in range(depth):
        value = [value]
    return value


def _mutate_string(rng: random.Random, text: str) -> str:
    for _ in range(rng.choice((1, 1, 2, 4))):
        i = rng.randrange(len(text) + 1)
        op = rng.randrange(4)
        if op == 0:
            text = text[:i] + rng.choice(ALPHABET) + text[i + 1:]
        elif op == 1:
            text = text[:i] + "".join(rng.choice(ALPHABET) for _ in range(rng.randrange(1, 4))) \
                + text[i:]
        elif op == 2:
            text = text[:i] + text[i + rng.randrange(1, 6):]
        else:
            text = text.upper() if rng.random() < 0.5 else text.lower()
    return text


def _nodes(value: Any) -> list[tuple[Any, Any]]:
    """(container, key) of every node under ``value`` (bounded)."""
    out: list[tuple[Any, Any]] = []
    stack = [value]
    while stack and len(out) < 400:
        node = stack.pop()
        if isinstance(node, dict):
            pairs = list(node.items())
        elif isinstance(node, list):
            pairs = list(enumerate(node))
        else:
            continue
        for key, item in pairs:
            out.append((node, key))
            stack.append(item)
    return out


#: Factors a subtree's numbers are scaled by: overflow, underflow, sign, degeneracy.
FACTORS = (-1, 1e6, 1e150, 1e300, 1e-300, 0.0, 1 + 1e-15)


def _scale(value: Any, factor: float) -> Any:
    if isinstance(value, bool) or not isinstance(value, int | float | list | dict):
        return value
    if isinstance(value, list):
        return [_scale(v, factor) for v in value]
    if isinstance(value, dict):
        return {k: _scale(v, factor) for k, v in value.items()}
    try:
        return value * factor
    except OverflowError:  # an int beyond float
        return math.inf


def mutate(rng: random.Random, body: Any, mild: bool = False) -> Any:
    """A structure-aware mutation of a JSON value (a deep copy of ``body``).

    ``mild``: one change that keeps the types (a leaf tweaked, numbers scaled, a list
    resized) — to get past the type checks into the computations.
    """
    value = json.loads(json.dumps(body))
    for _ in range(1 if mild else rng.choice((1, 1, 1, 2, 3))):
        nodes = _nodes(value)
        op = rng.choice((3, 3, 6, 7, 7)) if mild else rng.randrange(9)
        if not nodes or op == 0:  # the whole body of another type, or unknown fields
            if rng.random() < 0.5 and isinstance(value, dict):
                value[_string(rng)] = random_value(rng)
            else:
                value = random_value(rng)
            continue
        node, key = rng.choice(nodes)
        item = node[key]
        if op in (1, 2):
            node[key] = random_value(rng)
        elif op == 3 and isinstance(item, str):
            node[key] = _mutate_string(rng, item)
        elif op == 3 and isinstance(item, int | float):
            node[key] = rng.choice(ODD_NUMBERS) if rng.random() < 0.5 else \
                _scale(item, rng.choice(FACTORS))
        elif op == 4:
            del node[key]
        elif op == 5:
            node[key] = _nest(item, rng.choice((1, 2, 5, 10, 30, 200)))
        elif op == 6 and isinstance(item, list) and item:
            grow = rng.random() < 0.5 and len(item) <= 1000  # (no bodies of gigabytes)
            node[key] = item * rng.choice((0, 2, 50)) if grow else item[:-1]
        elif op == 7:
            node[key] = _scale(item, rng.choice(FACTORS))
        elif mild:
            pass
        elif isinstance(node, dict):
            node[_mutate_string(rng, str(key))] = node.pop(key)
        else:
            node[key] = random_value(rng)
    return value


def _deep(n: int, close: bool = True) -> bytes:
    return b"[" * n + (b"]" * n if close else b"")


#: Bytes every JSON route gets once, first: the known-hard inputs.
SPECIAL_BODIES: list[bytes] = [
    b"", b" ", b"null", b"[]", b"0", b'"x"', b"{", b"}", b'{"a":', b"\xef\xbb\xbf{}",
    b"\xff\xfe{\x00}\x00", b'{"kind": "\xff"}', b"NaN", b"-Infinity", b'{"x": NaN}',
    b'{"points": [[NaN, Infinity, -Infinity]]}', b"1" * 5000, b'{"n": ' + b"9" * 5000 + b"}",
    b'{"n": 1e999999}', b'{"n": -0}', b'{"s": "\\ud800"}', b'{"\\udfff": 1}',
    b'{"path": "\\ud800"}', b'{"path": "a\\u0000b"}', b'{"id": "\\u0000"}',
    '{"path": "\\ud800"}'.encode("utf-16"), '{"service": "\\udfff"}'.encode("utf-16-le"),
    '{"items": ["R1:\\ud800"]}'.encode("utf-32-be"), '{"kind": "line"}'.encode("utf-16"),
    _deep(100_000), _deep(100_000, close=False), b'{"a":' * 50_000, _deep(900),
    b'{"items": ' + _deep(5000) + b"}", b'{"a": 1, "a": [2]}', b"{" + b'"k": 0,' * 20000 + b"}",
    b" " * (MAX_BODY + 1),
]


def garble(rng: random.Random, raw: bytes) -> bytes:
    """The bytes of a body damaged."""
    r = rng.random()
    if r < 0.3 and raw:
        return raw[: rng.randrange(len(raw))]  # truncated
    if r < 0.55 and raw:
        out = bytearray(raw)
        for _ in range(rng.randrange(1, 4)):
            out[rng.randrange(len(out))] = rng.randrange(256)
        return bytes(out)
    if r < 0.7:
        return bytes(rng.randrange(256) for _ in range(rng.randrange(0, 40)))
    if r < 0.8:
        i = rng.randrange(len(raw) + 1)
        return raw[:i] + rng.choice((b"\xc3", b"\xed\xa0\x80", b"\x00", b"\\", b'"', b"\\u12",
                                     b"]]]]", b"}", b",", b":")) + raw[i:]
    if r < 0.9:
        return raw + rng.choice((b"x", b" {}", b"\n\n1", b"\x00", b"]"))
    return rng.choice(SPECIAL_BODIES[:-1])


CONTENT_TYPES = ["text/plain", "application/x-www-form-urlencoded",
                 "multipart/form-data; boundary=zz", "application/json; charset=latin-1",
                 "application/xml", "", "*/*", "application/json;;;=", "\x7f"]
ORIGINS = [BASE_URL, "http://127.0.0.1", "null", "http://evil.example", "http://[::1", "http://[",
           "http://127.0.0.1:99999", "file://", "http://127.0.0.1.evil", "::::", "http://%zz"]
HOSTS = ["evil.example", "127.0.0.1:8765", "[::1]:80", "[", "[::1", "", "localhost:",
         "127.0.0.1.nip.io", "a" * 3000, "testserver:1:2"]
METHODS = ["GET", "POST", "PUT", "DELETE", "PATCH", "OPTIONS", "HEAD"]


@dataclass
class Endpoint:
    """One method of one route; ``params``: path parameter → convertor (str, int, path)."""

    method: str
    path: str
    params: dict[str, str]

    @property
    def label(self) -> str:
        return f"{self.method} {self.path}"

    @property
    def json_body(self) -> bool:
        return self.method not in ("GET", "HEAD")


def endpoints(app: Any) -> list[Endpoint]:
    """Every HTTP route of ``app`` (a mount as ``{path}`` under it); websockets left out."""
    try:  # FastAPI ≥ 0.16x keeps an included router as one route: flatten it
        from fastapi.routing import iter_route_contexts
    except ImportError:
        flat: list[tuple[Any, Any]] = [(route, route) for route in app.routes]
    else:
        flat = [(ctx, ctx.original_route) for ctx in iter_route_contexts(app.routes)]
    out = []
    for effective, route in flat:
        if isinstance(route, Route):
            params = {name: type(conv).__name__.removesuffix("Convertor").lower()
                      for name, conv in route.param_convertors.items()}
            out.extend(Endpoint(m, effective.path, params)
                       for m in sorted((effective.methods or {"GET"}) - {"HEAD"}))
        elif isinstance(route, Mount):
            out.append(Endpoint("GET", effective.path + "/{path}", {"path": "path"}))
    return out


def _param(rng: random.Random, name: str, kind: str) -> str:
    seeds = PARAMS.get(name, ["x"])
    r = rng.random()
    if r < 0.35:
        value = rng.choice(seeds)
    elif r < 0.6:
        value = _mutate_string(rng, rng.choice(seeds))
    elif r < 0.7 and (kind == "integer" or all(v.lstrip("-").isdigit() for v in seeds)):
        value = str(rng.choice(ODD_NUMBERS))
    elif r < 0.8:
        value = rng.choice(["..", "../..", "..%2F..%2Fpyproject.toml", "%00", "%ff", "a/b",
                            ".hidden", "secret.py", "8.1.md/..", "~", "%2e%2e", "9" * 400,
                            "", " ", "é", "%", "?x=1", "#frag"])
    else:
        value = _string(rng)
    return value


def _url(rng: random.Random, ep: Endpoint) -> str:
    path = ep.path
    for name, kind in ep.params.items():
        value = _param(rng, name, kind)[:3000]  # httpx refuses URLs over 64 KiB
        data = value.encode("utf-8", "surrogatepass")
        raw = rng.random() < 0.3  # sometimes unquoted: '/' and '%' reach the router as such
        text = value if raw and value.isprintable() and value.isascii() else quote(data, safe="")
        path = path.replace("{" + name + "}", text)
    if rng.random() < 0.05:
        path += rng.choice(["?", "?a=1&a=2", "?%ff=%00", "?x=" + "y" * 5000, "?&&=&", "#x"])
    return path


@dataclass
class Case:
    method: str
    url: str
    headers: dict[str, str]
    content: bytes

    def __str__(self) -> str:
        body = self.content[:300] + (b"..." if len(self.content) > 300 else b"")
        return f"{self.method} {self.url[:300]} headers={self.headers} body={body!r}"


def make_case(rng: random.Random, ep: Endpoint) -> Case:
    """One fuzz request for ``ep``."""
    headers = dict(HEADERS)
    content = b""
    if ep.json_body:
        body = mutate(rng, rng.choice(BODIES.get(ep.path, [{}])), mild=rng.random() < 0.3)
        ascii_only = rng.random() < 0.7
        content = json.dumps(_tame(body), ensure_ascii=ascii_only).encode("utf-8", "surrogatepass")
        if rng.random() < 0.25:
            content = garble(rng, content)
            with contextlib.suppress(ValueError, RecursionError):
                parsed = json.loads(content)
                if (isinstance(parsed, str) and _slashed(parsed)) or any(
                        _slashed(text) for _, _, text in _strings(parsed)):
                    content = json.dumps(_tame(parsed)).encode()  # '/' let in by the damage
        content = content[:MAX_BODY + 1]  # refused as too large all the same
    elif rng.random() < 0.05:
        content = garble(rng, b'{"a": 1}')
    r = rng.random()
    if r < 0.05:
        headers["Content-Type"] = rng.choice(CONTENT_TYPES)
    elif r < 0.07:
        del headers["Content-Type"]
    r = rng.random()
    if r < 0.02:
        headers.pop("X-Plugcell")
    elif r < 0.03:
        headers["X-Plugcell"] = rng.choice(["0", "true", "1 ", ""])
    if rng.random() < 0.03:
        headers["Origin"] = rng.choice(ORIGINS)
    if rng.random() < 0.02:
        headers["Host"] = rng.choice(HOSTS)
    method = ep.method
    if rng.random() < 0.03:
        method = rng.choice(METHODS)
    return Case(method, _url(rng, ep), headers, content)


def _message_problem(value: Any) -> str:
    if not isinstance(value, str) or value.strip().lower() in GENERIC:
        return f"imprecise error message {value!r}"
    return ""


def judge(method: str, status: int, content_type: str, body: bytes) -> str:
    """What is wrong with an answer, or ``""``."""
    if status >= 500:
        return f"status {status}"
    if method == "HEAD":  # no body, by definition
        return ""
    is_json = content_type.startswith("application/json")
    if status < 400 and not is_json:
        return ""
    try:
        value = json.loads(body)
    except (ValueError, RecursionError):
        return f"status {status} with a body that is not JSON: {body[:200]!r}"
    if status < 400 and not (isinstance(value, dict) and value.get("ok") is False):
        return ""
    if not isinstance(value, dict):
        return f"status {status}: error body is not an object: {body[:200]!r}"
    if "errors" in value:
        errors = value["errors"]
        if value.get("ok") is not False or not isinstance(errors, dict) or not errors:
            return f"status {status}: malformed error body {body[:200]!r}"
        for problem in map(_message_problem, errors.values()):
            if problem:
                return problem
        return ""
    if status >= 400 and "detail" in value:  # Starlette's own: no route, wrong method …
        detail = value["detail"]
        if isinstance(detail, list) and detail:
            return next((p for p in (_message_problem(d.get("msg") if isinstance(d, dict)
                                                      else None) for d in detail) if p), "")
        return _message_problem(detail)
    return f"status {status}: error body without a message: {body[:200]!r}"


@dataclass
class Row:
    """The cases of one endpoint; ``accepted``: 2xx answers that are not a refusal."""

    endpoint: str
    cases: int = 0
    statuses: Counter[int] = field(default_factory=Counter)
    accepted: int = 0
    failures: int = 0
    max_ms: float = 0.0


@dataclass
class Report:
    cases: int
    seed: int
    seconds: float
    rows: list[Row]
    failures: list[str]

    @property
    def server_errors(self) -> int:
        return sum(n for row in self.rows for s, n in row.statuses.items() if s >= 500)

    def table(self) -> str:
        head = f"{'endpoint':<34}{'cases':>7}{'5xx':>5}{'bad':>5}{'max ms':>9}{'ok':>7}  statuses"
        lines = [head]
        for row in self.rows:
            hist = " ".join(f"{s}:{n}" for s, n in sorted(row.statuses.items()))
            fives = sum(n for s, n in row.statuses.items() if s >= 500)
            lines.append(f"{row.endpoint:<34}{row.cases:>7}{fives:>5}{row.failures:>5}"
                         f"{row.max_ms:>9.1f}{row.accepted:>7}  {hist}")
        total = Counter[int]()
        for row in self.rows:
            total.update(row.statuses)
        lines.append(f"{'all':<34}{self.cases:>7}{self.server_errors:>5}{len(self.failures):>5}"
                     f"{max(r.max_ms for r in self.rows):>9.1f}"
                     f"{sum(r.accepted for r in self.rows):>7}  "
                     + " ".join(f"{s}:{n}" for s, n in sorted(total.items())))
        return "\n".join(lines)


@contextlib.asynccontextmanager
async def web_app(workdir: Path) -> AsyncIterator[tuple[Any, httpx.AsyncClient]]:
    """The UI app on a controller and a drill service in a fresh cell, run in ``workdir``,
    and an HTTP client that calls it in-process (httpx's ASGI transport)."""
    docs = workdir / "docs"
    (docs / "results").mkdir(parents=True, exist_ok=True)
    (docs / "results" / "8.1.md").write_text("# 8.1\n")
    (docs / "results" / "fig.png").write_bytes(b"\x89PNG\r\n\x1a\n")
    (docs / "results" / "secret.py").write_text("x = 1\n")
    (workdir / "report.html").write_text("<html><body>report</body></html>")
    cell = f"fuzz{uuid.uuid4().hex[:12]}"
    old_home, old_cwd = os.environ.get("PLUGCELL_HOME"), Path.cwd()
    os.environ["PLUGCELL_HOME"] = str(workdir)
    os.chdir(workdir)
    try:
        controller = cell_controller(cell=cell, home=workdir)
        drill = GenericDevice(DrillService(SimulatedDrill(time_scale=0.001)), cell=cell)
        await controller.host.start()
        try:
            await drill.start()
            try:
                async with asyncio.timeout(20.0):  # the drill joins the cell
                    while controller.device_of("TOOL") is None:
                        await asyncio.sleep(0.05)
                app = create_app(controller, reports=ReportFiles(docs, [workdir / "report.html"]),
                                 manage=False)
                transport = httpx.ASGITransport(app=app)  # app exceptions are raised here
                async with httpx.AsyncClient(transport=transport, base_url=BASE_URL) as client:
                    yield app, client
            finally:
                await drill.close()
        finally:
            await controller.host.close()
    finally:
        os.chdir(old_cwd)
        if old_home is None:
            os.environ.pop("PLUGCELL_HOME", None)
        else:
            os.environ["PLUGCELL_HOME"] = old_home


class _Watchdog:
    """Ends the process if one case runs longer than ``seconds`` (a hang that does not
    yield to the event loop, which ``asyncio.timeout`` cannot end), printing it."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds
        self.case: tuple[float, str] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="fuzz-watchdog")
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(0.5):
            current = self.case
            if current is not None and time.monotonic() - current[0] > self.seconds:
                print(f"HANG: no answer in {self.seconds:g} s to {current[1]}", flush=True)
                os._exit(3)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2.0)


def fuzz_web(cases: int, seed: int, workdir: Path | None = None, hang_s: float = 20.0,
             watchdog: bool = False, specials: bool = True) -> Report:
    """Send ``cases`` requests spread over every endpoint; the report lists the failures.

    A case unanswered after ``hang_s`` is cancelled and fails; with ``watchdog`` one that
    cannot be cancelled ends the process after ``2 × hang_s`` (exit 3).  ``specials``:
    each JSON endpoint first gets :data:`SPECIAL_BODIES` (part of ``cases``).
    """
    with contextlib.ExitStack() as stack:
        if workdir is None:
            workdir = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="fuzzweb")))
        dog = _Watchdog(2 * hang_s) if watchdog else None
        if dog is not None:
            stack.callback(dog.stop)
        return asyncio.run(_fuzz(cases, seed, workdir, hang_s, dog, specials))


async def _fuzz(cases: int, seed: int, workdir: Path, hang_s: float, dog: _Watchdog | None,
                specials: bool) -> Report:
    rng = random.Random(f"web:{seed}")
    failures: list[str] = []
    started = time.perf_counter()
    async with web_app(workdir) as (app, client):
        eps = endpoints(app)
        rows = {ep.label: Row(ep.label) for ep in eps}
        queue: list[tuple[Endpoint, Case | None]] = []
        if specials:
            queue = [(ep, Case(ep.method, _url(rng, ep), dict(HEADERS), raw))
                     for ep in eps if ep.json_body for raw in SPECIAL_BODIES]
        queue = queue[:cases]
        queue += [(eps[i % len(eps)], None) for i in range(cases - len(queue))]
        for ep, case in queue:
            case = case or make_case(rng, ep)
            row = rows[ep.label]
            request = client.build_request(case.method, case.url, headers=case.headers,
                                           content=case.content)  # errors here: the fuzzer's
            if dog is not None:
                dog.case = (time.monotonic(), str(case))
            t0 = time.perf_counter()
            try:
                async with asyncio.timeout(hang_s):
                    r = await client.send(request)
                status, problem = r.status_code, judge(
                    case.method, r.status_code, r.headers.get("content-type", ""), r.content)
                if status < 300 and not problem and b'"ok":false' not in r.content[:200]:
                    row.accepted += 1
            except TimeoutError:
                status, problem = 504, f"no answer in {hang_s:g} s (a hang)"
            except Exception as exc:  # escaped the app: a crash
                status, problem = 500, f"{type(exc).__name__}: {exc}"[:500]
            row.max_ms = max(row.max_ms, (time.perf_counter() - t0) * 1e3)
            if dog is not None:
                dog.case = None
            row.cases += 1
            row.statuses[status] += 1
            if problem:
                row.failures += 1
                failures.append(f"{ep.label}: {problem} — for {case}")
    return Report(cases, seed, time.perf_counter() - started, list(rows.values()), failures)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=100_000, help="total requests")
    parser.add_argument("--seed", type=int, default=20261123)
    parser.add_argument("--hang-s", type=float, default=30.0,
                        help="a case unanswered this long fails (and one that cannot be "
                             "cancelled ends the run after twice as long, exit 3)")
    parser.add_argument("--show", type=int, default=20, help="failures printed")
    args = parser.parse_args(argv)
    logging.getLogger("plugcell").setLevel(logging.CRITICAL)  # the refusals are the point
    warnings.simplefilter("ignore", RuntimeWarning)  # numpy on degenerate points, refused
    report = fuzz_web(args.cases, args.seed, hang_s=args.hang_s, watchdog=True)
    print(f"web API fuzz: {report.cases} cases, seed {report.seed}, "
          f"{len(report.rows)} endpoints, {report.seconds:.1f} s "
          f"({report.cases / report.seconds:.0f} cases/s)")
    print(report.table())
    for line in report.failures[: args.show]:
        print("FAIL", line)
    if len(report.failures) > args.show:
        print(f"… {len(report.failures) - args.show} more failures")
    print(f"5xx: {report.server_errors}, failed cases: {len(report.failures)}")
    return 1 if report.failures else 0


if __name__ == "__main__":
    sys.exit(main())
