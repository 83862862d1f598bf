"""Checks shared by the streaming interfaces' configurations (RSI, EGM).

Each raises :class:`StreamConfigError` naming the field and why, so a link never starts
half-configured.
"""

from __future__ import annotations

import ipaddress
import math

__all__ = ["StreamConfigError", "check_host", "check_port", "six_values"]


class StreamConfigError(ValueError):
    """A stream configuration that cannot be used; the message names the field and why."""


def six_values(name: str, values: tuple[float, ...], positive: bool = True) -> tuple[float, ...]:
    """``values`` as six finite floats (``> 0`` if ``positive``), or the error naming them.

    Parameters
    ----------
    name : str
        The field, for the message.
    values : sequence of 6 float
        One value per axis.
    positive : bool
        Each must be ``> 0``.

    Returns
    -------
    tuple of 6 float
        The values.
    """
    vals = tuple(float(v) for v in values)
    if len(vals) != 6:
        raise StreamConfigError(f"{name}: expected 6 values (one per axis), got {len(vals)}")
    for i, v in enumerate(vals):
        if not math.isfinite(v) or (positive and v <= 0):
            raise StreamConfigError(f"{name}[{i}] = {v!r}: must be a finite number > 0")
    return vals


def check_host(what: str, host: str, why: str = "") -> str:
    """``host`` if it is a numeric IP address (what the controllers' configurations take).

    Parameters
    ----------
    what : str
        The field, for the message.
    host : str
        The address.
    why : str
        Said in the message after "expected an IP address" (``"RSI's IP_NUMBER is …"``).

    Returns
    -------
    str
        ``host``.
    """
    try:
        ipaddress.ip_address(host)
    except ValueError:
        raise StreamConfigError(f"{what} {host!r}: expected an IP address"
                                + (f" ({why})" if why else "")) from None
    return host


def check_port(what: str, port: int, allow_zero: bool) -> int:
    """``port`` if it is a UDP port (0, any free port, only if ``allow_zero``).

    Parameters
    ----------
    what : str
        The field, for the message.
    port : int
        The port.
    allow_zero : bool
        Whether 0 is accepted.

    Returns
    -------
    int
        ``port``.
    """
    if isinstance(port, bool) or not isinstance(port, int) or not (
            (0 if allow_zero else 1) <= port <= 65535):
        raise StreamConfigError(f"{what} {port!r}: expected a UDP port 1..65535")
    return port
