"""Which OPC UA session and user a method call of the gateway comes from.

asyncua hands a method callback only the object and the arguments; the user of the
session that called lives on the session (``InternalSession.user``).
:func:`capture_session_users` wraps each session the server creates so that, while one
of its calls runs, :func:`caller_name` and :func:`caller_session` say who calls, and so
that the gateway hears when the session closes.  This relies on asyncua's
``InternalServer.create_session`` and ``InternalSession.call``/``close_session``/``user``
— asyncua's public API has no way for a method callback to learn its session
(``Server.link_method`` callbacks get the object and the arguments; the server callbacks
of ``subscribe_server_callback`` cover reads, writes and monitored items only) — so
pyproject.toml pins asyncua to the tested minor version, :func:`capture_session_users`
refuses to start if those internals are gone, and the gateway refuses a call whose user
it cannot tell when anonymous sessions are off (docs/opcua.md, "Limits").
"""

from __future__ import annotations

import contextvars
from collections.abc import Awaitable, Callable
from typing import Any

from asyncua import Server
from asyncua.server.internal_session import InternalSession


def _init_names() -> tuple[str, ...]:
    import inspect

    return tuple(inspect.signature(InternalSession.__init__).parameters)


def _asyncua_version() -> str:
    from importlib.metadata import version

    return version("asyncua")

#: The OPC UA user of the method call being served (None: anonymous).
_caller_name: contextvars.ContextVar[str | None] = contextvars.ContextVar(
    "plugcell_opcua_caller", default=None
)
#: The OPC UA session of the method call being served (its id).
_caller_session: contextvars.ContextVar[int] = contextvars.ContextVar(
    "plugcell_opcua_session", default=0
)


def caller_name() -> str | None:
    """The user name of the session whose call is being served (None: anonymous)."""
    return _caller_name.get()


def caller_session() -> int:
    """An id of the session whose call is being served (0 outside a call)."""
    return _caller_session.get()


def capture_session_users(
    server: Server, closed: Callable[[int], Awaitable[None]]
) -> None:
    """Make the session's user known to method callbacks (:data:`_caller_name`), and
    tell ``closed(session id)`` when a session ends.

    asyncua hands a method callback only the object and the arguments; the user of
    the session that called lives on the session (``InternalSession.user``).  Each
    session this server creates gets its ``call`` wrapped to set the context
    variables for the duration of the call, and its ``close_session`` wrapped.
    """
    iserver = getattr(server, "iserver", None)
    create = getattr(iserver, "create_session", None)
    if (create is None or not hasattr(InternalSession, "call")
            or not hasattr(InternalSession, "close_session") or "user" not in _init_names()):
        raise RuntimeError(
            f"asyncua {_asyncua_version()} changed the internals the gateway relies on to "
            "know who calls (InternalServer.create_session, InternalSession.call, "
            "close_session, user; docs/opcua.md, 'Limits'): install the asyncua version "
            "pyproject.toml names")

    def create_session(*args: Any, **kwargs: Any) -> Any:
        session = create(*args, **kwargs)
        call = session.call

        close = session.close_session

        async def call_as_user(params: Any) -> Any:
            user = getattr(session, "user", None)
            token = _caller_name.set(getattr(user, "name", None))
            ident = _caller_session.set(id(session))
            try:
                return await call(params)
            finally:
                _caller_name.reset(token)
                _caller_session.reset(ident)

        async def close_session(*args: Any, **kwargs: Any) -> Any:
            try:
                return await close(*args, **kwargs)
            finally:
                await closed(id(session))

        session.call = call_as_user
        session.close_session = close_session
        return session

    iserver.create_session = create_session  # type: ignore[method-assign]
