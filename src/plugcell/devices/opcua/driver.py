"""The seam between the OPC UA device service and an OPC UA server: :class:`OpcUaDriver`.

The service (:mod:`plugcell.devices.opcua.device`) does plugcell's part — the device
map, which node each command acts on, the checks of the map against the server, the
connection watch, the reasons a sender reads — and asks a driver for the OPC UA
services (OPC 10000-4) it needs, one call each:

* :meth:`OpcUaDriver.connect` / :meth:`~OpcUaDriver.disconnect` — open and close a
  session (SecureChannel, CreateSession, ActivateSession);
* :meth:`~OpcUaDriver.server_state` — Read of ``Server.ServerStatus.State`` (the watch);
* :meth:`~OpcUaDriver.namespace_index` — the index of a namespace URI in the server's
  ``NamespaceArray`` (the map's ``nsu=`` node ids);
* :meth:`~OpcUaDriver.find`, :meth:`~OpcUaDriver.node_class`,
  :meth:`~OpcUaDriver.data_type`, :meth:`~OpcUaDriver.parent` — Read of a node's
  BrowseName, NodeClass, DataType attributes; Browse of its inverse hierarchical reference;
* :meth:`~OpcUaDriver.call`, :meth:`~OpcUaDriver.read`, :meth:`~OpcUaDriver.write` —
  Call, Read and Write of a Value;
* :meth:`~OpcUaDriver.subscribe` — CreateSubscription and CreateMonitoredItems for a
  variable's value changes, ended by :meth:`OpcUaSubscription.delete`.

Values cross the seam as plain Python (bool, int, float, str, nested lists of them as
the server sends them); what the service sends is an :class:`OpcUaValue`, the value with
its plugcell data type and shape, which a driver encodes as the variant of
:data:`DATA_TYPE_IDS`.  A server's refusal is an :class:`OpcUaStatusError` naming its
status code (``BadOutOfRange``…); a broken link is ``ConnectionError``, ``OSError`` or
``TimeoutError``, as asyncio raises them.

``plugcell serve opcua-device`` uses the asyncua client
(:class:`plugcell.devices.opcua.client.AsyncuaDriver`); an in-memory server model
(:mod:`plugcell.sim.drivers.opcua`) implements the same interface.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

from plugcell.framework.messages import DataTypes

__all__ = [
    "DATA_TYPE_IDS",
    "SERVER_STATE_RUNNING",
    "OpcUaDriver",
    "OpcUaDriverError",
    "OpcUaStatusError",
    "OpcUaSubscription",
    "OpcUaValue",
    "data_type_id",
]

#: The numeric NodeId (namespace 0) of the built-in DataType each plugcell data type is
#: sent as (OPC 10000-6 §5.1.2: Boolean 1, Byte 3, Int32 6, Double 11, String 12) —
#: also the variant type's number.
DATA_TYPE_IDS: dict[DataTypes, int] = {
    DataTypes.Boolean: 1,
    DataTypes.Byte: 3,
    DataTypes.Integer: 6,
    DataTypes.Double: 11,
    DataTypes.String: 12,
}

#: ``ServerState.Running`` (OPC 10000-5 §12.6), what :meth:`OpcUaDriver.server_state`
#: answers for a server at work.
SERVER_STATE_RUNNING = 0


def data_type_id(data_type: DataTypes) -> str:
    """The DataType NodeId text of ``data_type`` (``"i=11"`` for Double)."""
    return f"i={DATA_TYPE_IDS[data_type]}"


class OpcUaDriverError(RuntimeError):
    """The driver cannot do what was asked (a session it cannot open, a server it does
    not trust, a certificate it lacks); the message says why."""


class OpcUaStatusError(OpcUaDriverError):
    """The server answered a request with a Bad status code.

    Parameters
    ----------
    message : str
        What the server (or its stack) says about it.
    status : str
        The status code's name, e.g. ``"BadOutOfRange"`` (OPC 10000-4 §7.39).
    """

    def __init__(self, message: str, status: str) -> None:
        super().__init__(message)
        self.status = status


@dataclass(frozen=True)
class OpcUaValue:
    """A value the service sends (a method argument, a written value).

    ``value`` is a scalar (bool, int, float, str) or, for an array, its elements as a
    flat list in C order; ``dims`` is the shape of an array of more than one axis (the
    variant's ``ArrayDimensions``), None otherwise.
    """

    value: Any
    data_type: DataTypes
    is_array: bool = False
    dims: tuple[int, ...] | None = None


@runtime_checkable
class OpcUaSubscription(Protocol):
    """A running subscription of :meth:`OpcUaDriver.subscribe`."""

    async def delete(self) -> None:
        """End it (DeleteSubscriptions); no more values arrive afterwards."""
        ...


@runtime_checkable
class OpcUaDriver(Protocol):
    """An OPC UA client as the OPC UA device service needs it (module docstring).

    Node handles are the driver's own objects: :meth:`find` and :meth:`parent` return
    them and the other methods take them back.  Every method but :meth:`connect` needs an
    open session; one that finds the link gone raises ``ConnectionError`` (or ``OSError``,
    ``TimeoutError``).
    """

    endpoint: str
    """The server's endpoint URL (``opc.tcp://HOST:PORT/PATH``), for messages."""

    async def connect(self, client_name: str, timeout_s: float) -> None:
        """Open a session with the server (SecureChannel, CreateSession, ActivateSession).

        Parameters
        ----------
        client_name : str
            The application it connects as: the plugcell service's name (its application
            certificate, if the driver secures the channel).
        timeout_s : float
            The bound of each request of the session (s).

        Raises
        ------
        OpcUaDriverError
            The session cannot be opened; the message says why (the server's status
            code, a certificate refused or missing …).
        ConnectionError, OSError, TimeoutError
            The server cannot be reached.
        """
        ...

    async def disconnect(self) -> None:
        """Close the session (never raises; a link already gone counts as closed)."""
        ...

    async def server_state(self) -> int:
        """Read ``Server.ServerStatus.State`` (ns=0;i=2259), the connection watch's probe.

        Returns
        -------
        int
            The ServerState (:data:`SERVER_STATE_RUNNING` for a server at work).
        """
        ...

    async def namespace_index(self, uri: str) -> int:
        """The index of a namespace in the server's ``NamespaceArray``.

        Parameters
        ----------
        uri : str
            The namespace URI (of a map's ``nsu=`` node id).

        Returns
        -------
        int
            Its index on this server (indexes may change when the server restarts).

        Raises
        ------
        KeyError
            The server has no such namespace.
        """
        ...

    async def find(self, node_id: str) -> Any:
        """The node of a node id, once its BrowseName reads.

        Parameters
        ----------
        node_id : str
            OPC UA's text form with a namespace index, e.g. ``ns=2;s=Gripper.Close``.

        Returns
        -------
        object
            The driver's handle of the node.

        Raises
        ------
        OpcUaStatusError
            The server has no such node (``BadNodeIdUnknown``) or the id is not one
            (``BadNodeIdInvalid``).
        """
        ...

    async def node_class(self, node: Any) -> str:
        """The NodeClass attribute of ``node``.

        Returns
        -------
        str
            The class's name: ``"Object"``, ``"Variable"``, ``"Method"``, …
        """
        ...

    async def data_type(self, node: Any) -> str:
        """The DataType attribute of variable ``node``.

        Returns
        -------
        str
            Its NodeId text, ``"i=11"`` for Double (compare :func:`data_type_id`).

        Raises
        ------
        OpcUaStatusError
            ``node`` has no DataType (``BadAttributeIdInvalid``: not a variable).
        """
        ...

    async def parent(self, node: Any) -> Any | None:
        """The node that holds ``node`` (the source of its inverse hierarchical
        reference), or None if it has none."""
        ...

    async def call(self, obj: Any, method: Any, arguments: Sequence[OpcUaValue]
                   ) -> list[Any]:
        """Call a method (the Call service).

        Parameters
        ----------
        obj : object
            The object the method is called on (a handle of :meth:`find`).
        method : object
            The method (a handle of :meth:`find`).
        arguments : sequence of OpcUaValue
            Its input arguments, in order.

        Returns
        -------
        list
            Its output arguments' values, in order (empty for none).

        Raises
        ------
        OpcUaStatusError
            The server refuses (``BadMethodInvalid``, ``BadArgumentsMissing``,
            ``BadTypeMismatch``, the method's own status such as ``BadOutOfRange``).
        """
        ...

    async def read(self, node: Any) -> Any:
        """The Value attribute of variable ``node`` (a scalar, or a list for an array).

        Raises
        ------
        OpcUaStatusError
            The server refuses (``BadAttributeIdInvalid``, ``BadNotReadable`` …).
        """
        ...

    async def write(self, node: Any, value: OpcUaValue) -> None:
        """Write the Value attribute of variable ``node``.

        Raises
        ------
        OpcUaStatusError
            The server refuses (``BadTypeMismatch``, ``BadNotWritable`` …).
        """
        ...

    async def subscribe(self, node: Any, interval_ms: float,
                        on_value: Callable[[Any], None]) -> OpcUaSubscription:
        """Follow the Value of variable ``node`` (CreateSubscription, CreateMonitoredItems).

        Parameters
        ----------
        node : object
            The variable (a handle of :meth:`find`).
        interval_ms : float
            The publishing interval asked of the server (ms).
        on_value : callable
            Called with the value at once and then with each change the server
            publishes, on the caller's event loop, until the subscription is deleted.

        Returns
        -------
        OpcUaSubscription
            The subscription, to :meth:`~OpcUaSubscription.delete`.
        """
        ...
