"""Request hygiene of the controller's web UI: local use only, readable bodies.

The UI can rewire a cell and make robots move, so a page from elsewhere must not
drive it through the engineer's browser:

* the ``Host`` header must name this machine (no DNS rebinding);
* a request with an ``Origin`` must come from this very server;
* every state-changing request carries the header ``X-Plugcell: 1`` — a header a
  page of another origin cannot add without a CORS pre-flight, which this server
  never grants.

Bodies are JSON objects of at most :data:`MAX_BODY` bytes; anything else is a
``400`` with ``{"errors": {"_": reason}}``.
"""

from __future__ import annotations

import json
import re
import sys
from typing import Any
from urllib.parse import urlsplit

from starlette.requests import HTTPConnection, Request
from starlette.responses import JSONResponse

MAX_BODY = 8 * 1024 * 1024
LOCAL_HOSTS = {"localhost", "127.0.0.1", "::1", "[::1]", "testserver"}
HEADER = "x-plugcell"

__all__ = ["BadRequestError", "RefusedError", "check_connection", "error_response", "json_body"]


class BadRequestError(Exception):
    """A request the UI refuses: ``errors`` maps fields (``_`` for the whole) to why."""

    def __init__(self, errors: dict[str, str], status: int = 400) -> None:
        super().__init__("; ".join(errors.values()))
        self.errors = errors
        self.status = status


class RefusedError(BadRequestError):
    """Input the UI understood and refuses (a field error): ``200`` with ``ok: false``.

    Not an HTTP error: the request was fine, its content was not — and a browser
    would report every 4xx as a console error.
    """

    def __init__(self, errors: dict[str, str]) -> None:
        super().__init__(errors, 200)


def error_response(errors: dict[str, str], status: int = 400) -> JSONResponse:
    return JSONResponse({"ok": False, "errors": errors}, status_code=status)


def _host(value: str) -> str:
    if value.startswith("["):
        return value[: value.find("]") + 1]
    return value.rsplit(":", 1)[0] if value.count(":") == 1 else value


def check_connection(conn: HTTPConnection, extra_hosts: set[str] | frozenset[str] = frozenset()
                     ) -> str:
    """Why ``conn`` is refused, or ``""``."""
    host = _host(conn.headers.get("host", ""))
    if host not in LOCAL_HOSTS and host not in extra_hosts:
        return f"host {host!r} is not this machine"
    origin = conn.headers.get("origin")
    if origin and origin != "null":
        try:
            netloc = urlsplit(origin).netloc
        except ValueError:  # "http://[": not a URL
            return f"malformed Origin header {origin!r}"
        if _host(netloc) != host or netloc != conn.headers.get("host", ""):
            return f"requests from {origin} are not accepted"
    writes = conn.scope["type"] == "http" and conn.scope.get("method") not in ("GET", "HEAD")
    if writes and conn.headers.get(HEADER) != "1":
        return f"missing header {HEADER.title()}: 1"
    return ""


async def json_body(request: Request) -> dict[str, Any]:
    """The request's JSON object (BadRequestError if it is not one)."""
    size = request.headers.get("content-length")
    if size is not None and (not size.isdigit() or int(size) > MAX_BODY):
        raise BadRequestError({"_": f"body larger than {MAX_BODY} bytes"}, 413)
    raw = await request.body()
    if len(raw) > MAX_BODY:
        raise BadRequestError({"_": f"body larger than {MAX_BODY} bytes"}, 413)
    try:
        value = json.loads(raw or b"{}", parse_int=_integer)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise BadRequestError({"_": f"body is not JSON: {exc}"}) from None
    except RecursionError:
        raise BadRequestError({"_": "body is not JSON this server reads: nested too deeply"}
                              ) from None
    except ValueError as exc:  # an integer beyond the numbers of this API (_integer)
        raise BadRequestError({"_": f"body is not JSON this server reads: {exc}"}) from None
    if not isinstance(value, dict):
        raise BadRequestError({"_": "body must be a JSON object"})
    if _SURROGATE.search(raw) or b"\0" in raw:  # NUL bytes: UTF-16 or UTF-32
        _check_text(value)
    return value


#: The largest integer a body may hold: beyond it no number of the API (a float) can
#: stand for it, and converting it raises OverflowError deep inside.
_MAX_INT = int(sys.float_info.max)


def _integer(text: str) -> int:
    # a length check first: int() of thousands of digits is slow (and refused past 4300)
    if len(text) > 310 or abs(value := int(text)) > _MAX_INT:
        raise ValueError(f"the integer {text[:12]}… ({len(text.lstrip('-'))} digits) is beyond "
                         f"±{sys.float_info.max:.1e}")
    return value


#: A ``\uD800``–``\uDFFF`` escape or such a code point in UTF-8 (``json.loads`` decodes
#: bytes with ``surrogatepass``): the ways a UTF-8 body gives a string that is not text.
_SURROGATE = re.compile(rb"\\u[dD][89a-fA-F]|\xed[\xa0-\xbf]")


def _check_text(value: Any) -> None:
    """BadRequestError if a string (or key) of ``value`` holds a lone surrogate.

    Such a string cannot be written as UTF-8: not a name, a path or a log line.
    """
    stack = [value]
    while stack:  # iterative: the body may be nested deeper than the recursion limit
        node = stack.pop()
        if isinstance(node, dict):
            stack.extend(node)
            stack.extend(node.values())
        elif isinstance(node, list):
            stack.extend(node)
        elif isinstance(node, str):
            try:
                node.encode("utf-8")
            except UnicodeEncodeError as exc:
                bad = node[exc.start]
                raise BadRequestError({"_": f"body is not Unicode text: a string holds the "
                                            f"lone surrogate \\u{ord(bad):04x}"}) from None
