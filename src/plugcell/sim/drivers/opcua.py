"""An OPC UA server's address space in memory, and a client of it (the OPC UA device
family's simulated driver, an :class:`~plugcell.devices.opcua.driver.OpcUaDriver`).

:class:`OpcUaServerModel` holds what a server's address space holds for a device
(OPC 10000-3): namespaces, objects, variables of a built-in DataType and a ValueRank
(scalar or array), methods with typed input arguments, each node with its NodeClass,
BrowseName and the node that holds it; and it answers as a server does — a Bad status
code (OPC 10000-4 §7.39) for a node that does not exist (``BadNodeIdUnknown``), an
attribute a node class has not (``BadAttributeIdInvalid``), a value of another type
(``BadTypeMismatch``), a method not of the object it is called on
(``BadMethodInvalid``), too few or too many arguments (``BadArgumentsMissing``,
``BadTooManyArguments``), and whatever a method's handler refuses.  :meth:`stop` is
the server going away: every session ends, a client's next request fails with
``ConnectionError``, a new session is refused until :meth:`start`.

:class:`SimulatedOpcUaDriver` is a client of such a model, with the driver interface
the service uses for a real server (:class:`plugcell.devices.opcua.client.AsyncuaDriver`):
values cross as plain Python, a subscription publishes the variable's value at once and
then each change, sampled every publishing interval, on the client's event loop.
"""

from __future__ import annotations

import asyncio
import contextlib
import copy
import re
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from plugcell.devices.opcua.driver import (
    DATA_TYPE_IDS,
    SERVER_STATE_RUNNING,
    OpcUaStatusError,
    OpcUaValue,
)
from plugcell.framework.messages import DataTypes

__all__ = [
    "GRIPPER_NAMESPACE",
    "OpcUaServerModel",
    "SimNode",
    "SimulatedGripper",
    "SimulatedOpcUaDriver",
]

#: The namespace of :class:`SimulatedGripper`'s nodes.
GRIPPER_NAMESPACE = "urn:plugcell:test:gripper"
#: The standard namespace (index 0) and the ``Objects`` folder (ns=0;i=85).
UA_NAMESPACE = "http://opcfoundation.org/UA/"
OBJECTS_FOLDER = "i=85"
_NODE_ID = re.compile(r"^(?:ns=(\d+);)?([isgb])=(.+)$")

#: A method's handler: its input arguments (plain Python) → its output arguments; it
#: refuses with :class:`~plugcell.devices.opcua.driver.OpcUaStatusError`.
MethodHandler = Callable[[list[Any]], Awaitable[list[Any]]]


def _bad(status: str, what: str) -> OpcUaStatusError:
    return OpcUaStatusError(f"{what} ({status})", status)


def _key(node_id: str) -> tuple[int, str, str]:
    """(namespace index, identifier type, identifier) of a node id text."""
    match = _NODE_ID.match(node_id)
    if match is None:
        raise _bad("BadNodeIdInvalid", f"{node_id!r} is not a node id")
    return int(match.group(1) or 0), match.group(2), match.group(3)


@dataclass(eq=False)
class SimNode:
    """One node of the model."""

    node_id: str
    node_class: str
    """``Object``, ``Variable`` or ``Method``."""
    browse_name: str
    parent: SimNode | None = None
    data_type: DataTypes | None = None
    """A variable's DataType."""
    is_array: bool = False
    """A variable's ValueRank: an array (1) or a scalar (−1)."""
    value: Any = None
    inputs: tuple[DataTypes, ...] = ()
    """A method's input arguments (each a scalar of its type)."""
    handler: MethodHandler | None = None
    components: list[SimNode] = field(default_factory=list)


class OpcUaServerModel:
    """An OPC UA server's address space for a device (module docstring).

    Parameters
    ----------
    endpoint : str
        The endpoint URL it answers at (only for messages: nothing listens).
    """

    def __init__(self, endpoint: str = "opc.tcp://simulated:4840") -> None:
        self.endpoint = endpoint
        self.namespaces = [UA_NAMESPACE]
        self.running = True
        self.generation = 0
        """Counts the server's starts: a session of an earlier one is gone."""
        self.sessions: list[str] = []
        """The application names of the sessions opened, in order."""
        self.calls: list[tuple[str, list[Any]]] = []
        """Each method called: its BrowseName and input arguments, in order."""
        self._nodes: dict[tuple[int, str, str], SimNode] = {}
        self.objects = self._add(SimNode(OBJECTS_FOLDER, "Object", "Objects"))

    # -- building the address space ----------------------------------------------------

    def register_namespace(self, uri: str) -> int:
        """The index of namespace ``uri`` (added at the end if new)."""
        if uri not in self.namespaces:
            self.namespaces.append(uri)
        return self.namespaces.index(uri)

    def _add(self, node: SimNode) -> SimNode:
        key = _key(node.node_id)
        if key in self._nodes:
            raise ValueError(f"node {node.node_id} exists already")
        self._nodes[key] = node
        if node.parent is not None:
            node.parent.components.append(node)
        return node

    def add_object(self, node_id: str, browse_name: str, parent: SimNode | None = None
                   ) -> SimNode:
        """An object held by ``parent`` (default: the Objects folder)."""
        return self._add(SimNode(node_id, "Object", browse_name, parent or self.objects))

    def add_variable(self, node_id: str, browse_name: str, parent: SimNode,
                     data_type: DataTypes, value: Any, *, is_array: bool = False) -> SimNode:
        """A variable of ``data_type`` (a scalar, or an array if ``is_array``)."""
        node = SimNode(node_id, "Variable", browse_name, parent, data_type=data_type,
                       is_array=is_array)
        node.value = self._checked(node, value)
        return self._add(node)

    def add_method(self, node_id: str, browse_name: str, parent: SimNode,
                   handler: MethodHandler, inputs: Sequence[DataTypes] = ()) -> SimNode:
        """A method of object ``parent``, taking scalar ``inputs``, run by ``handler``."""
        return self._add(SimNode(node_id, "Method", browse_name, parent, inputs=tuple(inputs),
                                 handler=handler))

    def set_value(self, node: SimNode, value: Any) -> None:
        """What the device does to its variable (a sensor's new reading)."""
        node.value = self._checked(node, value)

    # -- the server's life ---------------------------------------------------------------

    def stop(self) -> None:
        """The server goes away: its sessions end, new ones are refused."""
        self.running = False

    def start(self) -> None:
        """The server is back (sessions of before stay ended)."""
        if not self.running:
            self.running = True
            self.generation += 1

    # -- answering -----------------------------------------------------------------------

    def node(self, node_id: str) -> SimNode:
        """The node of ``node_id`` (``BadNodeIdUnknown`` if none)."""
        found = self._nodes.get(_key(node_id))
        if found is None:
            raise _bad("BadNodeIdUnknown", f"no node {node_id}")
        return found

    def _checked(self, node: SimNode, value: Any) -> Any:
        """``value`` as variable ``node`` holds it (``BadTypeMismatch`` if it cannot)."""
        assert node.data_type is not None
        items = value if node.is_array else [value]
        if not isinstance(items, list) or node.is_array != isinstance(value, list):
            raise _bad("BadTypeMismatch",
                       f"{node.browse_name} holds {'an array' if node.is_array else 'a scalar'}")
        kinds = {DataTypes.Boolean: (bool,), DataTypes.Byte: (int,), DataTypes.Integer: (int,),
                 DataTypes.Double: (float, int), DataTypes.String: (str,)}[node.data_type]
        for item in items:
            if not isinstance(item, kinds) or (isinstance(item, bool)
                                               and node.data_type is not DataTypes.Boolean):
                raise _bad("BadTypeMismatch", f"{item!r} is not a {node.data_type.value}")
        if node.data_type is DataTypes.Double:
            return [float(v) for v in items] if node.is_array else float(value)
        return copy.deepcopy(value)

    def read(self, node: SimNode) -> Any:
        if node.node_class != "Variable":
            raise _bad("BadAttributeIdInvalid", f"{node.browse_name} has no Value")
        return copy.deepcopy(node.value)

    def write(self, node: SimNode, value: OpcUaValue) -> None:
        if node.node_class != "Variable":
            raise _bad("BadAttributeIdInvalid", f"{node.browse_name} has no Value")
        if value.data_type is not node.data_type:
            raise _bad("BadTypeMismatch", f"{node.browse_name} holds {node.data_type}, not "
                       f"{value.data_type.value}")
        node.value = self._checked(node, value.value)

    async def call(self, obj: SimNode, method: SimNode, arguments: Sequence[OpcUaValue]
                   ) -> list[Any]:
        if method.node_class != "Method" or method.handler is None:
            raise _bad("BadMethodInvalid", f"{method.browse_name} is not a method")
        if method not in obj.components:
            raise _bad("BadMethodInvalid", f"{method.browse_name} is not a method of "
                       f"{obj.browse_name}")
        if len(arguments) < len(method.inputs):
            raise _bad("BadArgumentsMissing", f"{method.browse_name} takes "
                       f"{len(method.inputs)} arguments, got {len(arguments)}")
        if len(arguments) > len(method.inputs):
            raise _bad("BadTooManyArguments", f"{method.browse_name} takes "
                       f"{len(method.inputs)} arguments, got {len(arguments)}")
        for k, (arg, want) in enumerate(zip(arguments, method.inputs, strict=True)):
            if arg.data_type is not want or arg.is_array:
                raise _bad("BadTypeMismatch", f"{method.browse_name}: argument {k + 1} must "
                           f"be a {want.value} scalar")
        values = [copy.deepcopy(a.value) for a in arguments]
        self.calls.append((method.browse_name, values))
        return list(await method.handler(values))


class SimulatedOpcUaDriver:
    """A client of an :class:`OpcUaServerModel` (module docstring).

    Parameters
    ----------
    server : OpcUaServerModel
        The server it connects to.
    """

    def __init__(self, server: OpcUaServerModel) -> None:
        self.server = server
        self.endpoint = server.endpoint
        self._generation: int | None = None
        """The server's start the session belongs to (None: no session)."""

    def _session(self) -> OpcUaServerModel:
        if self._generation is None:
            raise ConnectionError(f"no session with {self.endpoint}")
        if not self.server.running or self.server.generation != self._generation:
            raise ConnectionError(f"{self.endpoint} closed the connection")
        return self.server

    async def connect(self, client_name: str, timeout_s: float) -> None:
        await asyncio.sleep(0)
        if not self.server.running:
            raise ConnectionRefusedError(f"{self.endpoint} refused the connection")
        self._generation = self.server.generation
        self.server.sessions.append(client_name)

    async def disconnect(self) -> None:
        self._generation = None

    async def server_state(self) -> int:
        await asyncio.sleep(0)
        self._session()
        return SERVER_STATE_RUNNING

    async def namespace_index(self, uri: str) -> int:
        namespaces = self._session().namespaces
        if uri not in namespaces:
            raise KeyError(uri)
        return namespaces.index(uri)

    async def find(self, node_id: str) -> SimNode:
        return self._session().node(node_id)

    async def node_class(self, node: SimNode) -> str:
        self._session()
        return node.node_class

    async def data_type(self, node: SimNode) -> str:
        self._session()
        if node.data_type is None:
            raise _bad("BadAttributeIdInvalid", f"{node.browse_name} has no DataType")
        return f"i={DATA_TYPE_IDS[node.data_type]}"

    async def parent(self, node: SimNode) -> SimNode | None:
        self._session()
        return node.parent

    async def call(self, obj: SimNode, method: SimNode, arguments: Sequence[OpcUaValue]
                   ) -> list[Any]:
        return await self._session().call(obj, method, arguments)

    async def read(self, node: SimNode) -> Any:
        await asyncio.sleep(0)
        return self._session().read(node)

    async def write(self, node: SimNode, value: OpcUaValue) -> None:
        await asyncio.sleep(0)
        self._session().write(node, value)

    async def subscribe(self, node: SimNode, interval_ms: float,
                        on_value: Callable[[Any], None]) -> _Subscription:
        first = self._session().read(node)  # BadAttributeIdInvalid for a non-variable
        return _Subscription(self, node, interval_ms / 1000.0, on_value, first)


class _Subscription:
    """A subscription of one variable: its value at once, then each change, sampled every
    publishing interval while the session lasts."""

    def __init__(self, driver: SimulatedOpcUaDriver, node: SimNode, interval_s: float,
                 on_value: Callable[[Any], None], first: Any) -> None:
        self.driver, self.node, self.interval_s = driver, node, max(interval_s, 0.001)
        self.on_value = on_value
        on_value(first)
        self._task = asyncio.get_running_loop().create_task(self._publish(first))

    async def _publish(self, last: Any) -> None:
        while True:
            await asyncio.sleep(self.interval_s)
            try:
                value = self.driver._session().read(self.node)
            except ConnectionError:
                return  # the session is gone: so is its subscription
            if value != last:
                last = value
                self.on_value(value)

    async def delete(self) -> None:
        self._task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self._task
        self.driver._session()  # DeleteSubscriptions needs the session


class SimulatedGripper:
    """A gripper behind an OPC UA server — the one of the tests'
    ``tests/opcua/js/gripper_server.js`` (node-opcua), in the model: in namespace
    :data:`GRIPPER_NAMESPACE` (index 2), object ``Gripper`` with methods ``Open()`` and
    ``Close(Force: Double) → Reached: Double`` (0 < force ≤ 100 N, else
    ``BadOutOfRange``; the force ramps up in 5 steps of 20 ms), variables ``Force``
    (Double, N), ``Closed`` (Boolean) and ``Limits`` (Double array); :meth:`creep` is the
    closed jaw's creeping force (a live value), run as a task beside the service."""

    def __init__(self, server: OpcUaServerModel) -> None:
        server.register_namespace("urn:plugcell:sim:other")  # so the gripper's is ns=2
        ns = server.register_namespace(GRIPPER_NAMESPACE)
        self.server = server
        obj = server.add_object(f"ns={ns};s=Gripper", "Gripper")
        self.force = server.add_variable(f"ns={ns};s=Gripper.Force", "Force", obj,
                                         DataTypes.Double, 0.0)
        self.closed = server.add_variable(f"ns={ns};s=Gripper.Closed", "Closed", obj,
                                          DataTypes.Boolean, False)
        self.limit = server.add_variable(f"ns={ns};s=Gripper.Limits", "Limits", obj,
                                         DataTypes.Double, [0.0, 100.0], is_array=True)
        server.add_method(f"ns={ns};s=Gripper.Open", "Open", obj, self.open)
        server.add_method(f"ns={ns};s=Gripper.Close", "Close", obj, self.close,
                          [DataTypes.Double])

    async def open(self, args: list[Any]) -> list[Any]:
        """``Open()``: force 0, not closed."""
        self.server.set_value(self.force, 0.0)
        self.server.set_value(self.closed, False)
        return []

    async def close(self, args: list[Any]) -> list[Any]:
        """``Close(Force)``: ramp up to it; the force reached."""
        target = args[0]
        if not 0 < target <= 100:
            raise OpcUaStatusError(f"force {target} N outside (0, 100] (BadOutOfRange)",
                                   "BadOutOfRange")
        for step in range(1, 6):
            self.server.set_value(self.force, target * step / 5)
            await asyncio.sleep(0.02)
        self.server.set_value(self.closed, True)
        return [self.force.value]

    async def creep(self) -> None:
        """Forever: every 50 ms a closed jaw's force grows by 1 mN."""
        while True:
            await asyncio.sleep(0.05)
            if self.closed.value:
                self.server.set_value(self.force, self.force.value + 0.001)
