"""``plugcell serve opcua-device``: an OPC UA server's device as a plugcell service.

The service's catalogue is its device map (:mod:`plugcell.devices.opcua.device_map`); its
device interface is an asyncua client of ``endpoint``:

* ``method`` commands call the method (input data — and the option, if the map
  says so — as its arguments; a SingleData command's data is its first output);
* ``write`` commands write their input to a variable;
* ``read`` commands read a variable (SingleData);
* ``subscribe`` commands stream a variable's value changes (an OPC UA
  subscription; MultipleData) until the sender's StopData deletes it.

At start the service connects and resolves every node of the map: a node that does
not exist, is of the wrong node class, or holds another data type than the map
declares stops it with the reason (the file, the command, the node).  Then a watch
reads the server's state every ``watch_s``: a lost connection makes the service
``ConnectionState Error``, fails a running stream (``device feedback 'connection to
… lost: …' while streaming``) and every command until the connection is back; the
service keeps reconnecting every ``watch_s`` and re-resolves the map each time (the
server's namespace indexes may have changed), then reports Online again.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
from collections.abc import Coroutine
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from asyncua import Client, Node, ua

from plugcell.devices.opcua.arguments import VARIANT_TYPES
from plugcell.devices.opcua.device_map import DeviceMap, MappedCommand, load_device_map
from plugcell.devices.opcua.server_trust import ServerTrust
from plugcell.devices.params import flag
from plugcell.framework.declaration import Declaration
from plugcell.framework.messages import Command, ConnectionStates, DataTypes
from plugcell.framework.service import DeviceError, GenericDevice

log = logging.getLogger("plugcell.devices.opcua.device")
if logging.getLogger("asyncua").level == logging.NOTSET:
    # asyncua warns of things nobody can act on (revised session timeouts …); its
    # errors still show (a program that wants its warnings sets the level before)
    logging.getLogger("asyncua").setLevel(logging.ERROR)

#: Built-in DataType NodeIds (ns=0) of the variant types a map may declare.
_DATATYPE_IDS = {vtype: ua.NodeId(vtype.value) for vtype in VARIANT_TYPES.values()}


@dataclass
class _Resolved:
    """The nodes of one mapped command on the connected server."""

    node: Node | None = None
    object: Node | None = None


class OpcUaDevice:
    """A device behind an OPC UA server, mapped to a catalogue by a device map (the device
    a :class:`~plugcell.framework.service.GenericDevice` hosts)."""

    declaration = Declaration(
        kind="opcua-device",
        info="an OPC UA device (plugcell serve opcua-device --endpoint … --map …)")
    """The kind's; each instance declares its map's catalogue, vendor and name."""
    params: ClassVar[dict[str, Any]] = {
        "endpoint": str, "map": str, "watch_s": float, "certs": str, "user": str,
        "trust": str, "server_uri": str, "insecure_accept_any": flag,
    }

    def __init__(
        self,
        *,
        endpoint: str = "",
        map: str | Path | DeviceMap = "",
        watch_s: float = 1.0,
        certs: str | Path = "",
        user: str = "",
        trust: str | Path = "",
        server_uri: str = "",
        insecure_accept_any: bool = False,
    ) -> None:
        if not endpoint:
            raise ValueError("opcua-device needs --endpoint opc.tcp://HOST:PORT")
        if not map:
            raise ValueError("opcua-device needs --map FILE (docs/opcua.md)")
        if not certs and not insecure_accept_any:
            raise ValueError(
                f"opcua-device cannot authenticate the server of {endpoint} without a "
                "certificate of its own: give --param certs=DIR (SecurityPolicy Basic256Sha256, "
                "the server's certificate checked against the cell's CA and --trust DIR), or, "
                "on a test bench only, --insecure-accept-any (SecurityPolicy None, any server)")
        if (trust or server_uri) and not certs:
            raise ValueError("--trust and server_uri check the server's certificate, which only "
                             "a secured connection has: give --param certs=DIR too")
        self.map = map if isinstance(map, DeviceMap) else load_device_map(map)
        # the catalogue and identity come from the map
        self.declaration = Declaration(
            kind=self.declaration.kind, commands=tuple(c.command for c in self.map.commands),
            default_name=self.map.name, vendor=self.map.vendor,
            info=self.map.info or f"OPC UA device at {endpoint}")
        self.service: GenericDevice | None = None
        self.endpoint = endpoint
        self.watch_s = watch_s
        self.certs = Path(certs) if certs else None
        """The cell's certificate folder: connect with Basic256Sha256 SignAndEncrypt as
        ``<certs>/<name>.opcua.pem`` (``plugcell certs opcua NAME``)."""
        self.user = user
        """OPC UA user name; its password is ``$PLUGCELL_OPCUA_PASSWORD``."""
        self.trust = Path(trust) if trust else None
        """A folder of trusted certificates (pinned servers, authorities) and revocation
        lists, beside the cell's CA (:mod:`plugcell.devices.opcua.server_trust`)."""
        self.server_uri = server_uri
        """The application URI the server must have ("": the one it says it has)."""
        self.insecure_accept_any = insecure_accept_any
        """Accept any server, its certificate unchecked (a test bench only; logged)."""
        self.client: Client | None = None
        self._nodes: dict[str, _Resolved] = {}
        self._lost = ""
        """Why the connection is down ("" while connected)."""
        self._watch: asyncio.Task[None] | None = None
        self._subscription: Any = None

    def bind(self, service: GenericDevice) -> None:
        self.service = service

    @property
    def host(self) -> GenericDevice:
        """The service hosting this device."""
        assert self.service is not None, "OpcUaDevice used before a service hosts it"
        return self.service

    @property
    def name(self) -> str:
        """The service's name (the map's before a service hosts the device)."""
        return self.service.name if self.service is not None else self.declaration.name()

    # -- connection --------------------------------------------------------------------

    async def connect(self) -> None:
        """Connect and resolve the map (DeviceError with the reason if either fails)."""
        if self.insecure_accept_any:
            log.warning("%s: --insecure-accept-any: accepting whatever server answers at %s, "
                        "its certificate unchecked (a test bench only)", self.name,
                        self.endpoint)
        await self._open()
        self.host.connection_state.post(ConnectionStates.Online)
        self._watch = asyncio.create_task(self._watch_connection(), name=f"{self.name}-watch")

    async def _open(self) -> None:
        log.info("%s: connecting to %s", self.name, self.endpoint)
        client = Client(self.endpoint, timeout=max(2.0, self.watch_s * 2))
        if self.user:
            client.set_user(self.user)
            client.set_password(os.environ.get("PLUGCELL_OPCUA_PASSWORD", ""))
        try:
            if self.certs is not None:
                await self._secure(client, self.certs)
            await _cancellable(client.connect())
        except DeviceError as exc:  # the server's certificate refused (server_trust)
            raise DeviceError(f"cannot connect to {self.endpoint}: {exc}") from None
        except (TimeoutError, OSError, ValueError, ua.UaError) as exc:
            raise DeviceError(f"cannot connect to {self.endpoint}: {_why(exc)}") from None
        try:
            self._nodes = {m.command.name: await self._resolve(client, m)
                           for m in self.map.commands}
        except BaseException:
            with contextlib.suppress(Exception):
                await client.disconnect()
            raise
        self.client = client
        self._lost = ""

    async def _secure(self, client: Client, folder: Path) -> None:
        """Basic256Sha256 SignAndEncrypt with this service's application certificate."""
        from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
        from asyncua.crypto.uacrypto import CertProperties

        from plugcell.devices.opcua.certificates import application_uri, certificate_paths, uri_of

        cert, key = certificate_paths(folder, self.name)
        if not cert.is_file() or not key.is_file():
            raise DeviceError(f"no OPC UA certificate {cert}: run `plugcell certs opcua "
                              f"{self.name} --dir {folder}`")
        client.application_uri = uri_of(cert) or application_uri(self.name)
        if not self.insecure_accept_any:  # read again at each connection: rotations
            client.certificate_validator = ServerTrust.load(
                self.endpoint, cell_certs=folder, trust=self.trust,
                expected_uri=self.server_uri)
        await client.set_security(
            SecurityPolicyBasic256Sha256, CertProperties(cert, "pem"), CertProperties(key, "pem"),
            mode=ua.MessageSecurityMode.SignAndEncrypt)

    async def disconnect(self) -> None:
        if self._watch is not None:
            self._watch.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._watch
        await self._close_client()
        self.host.connection_state.post(ConnectionStates.Offline)

    async def _close_client(self) -> None:
        client, self.client, self._subscription = self.client, None, None
        if client is not None:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(client.disconnect(), 2.0)

    async def _watch_connection(self) -> None:
        """Notice a lost connection, fail what runs, reconnect (module docstring)."""
        state = ua.NodeId(ua.ObjectIds.Server_ServerStatus_State)
        while True:
            await asyncio.sleep(self.watch_s)
            if self.client is not None:
                try:
                    await asyncio.wait_for(self.client.get_node(state).read_value(),
                                           self.watch_s * 2)
                    continue
                except Exception as exc:  # any failure of the link is a lost connection
                    self._connection_lost(_why(exc))
                    await self._close_client()
            try:
                await self._open()
            except Exception as exc:
                self._lost = f"connection to {self.endpoint} lost: {_why(exc)} (reconnecting)"
                continue
            log.warning("%s: reconnected to %s", self.name, self.endpoint)
            self.host.connection_state.post(ConnectionStates.Online)

    def _connection_lost(self, why: str) -> None:
        self._lost = f"connection to {self.endpoint} lost: {why}"
        log.warning("%s: %s", self.name, self._lost)
        self.host.connection_state.post(ConnectionStates.Error)
        if self._subscription is not None:  # a stream is running: it ends Failed
            self.host.cmd_feedback.post(self._lost)

    # -- the map on the server ---------------------------------------------------------

    async def _resolve(self, client: Client, mapped: MappedCommand) -> _Resolved:
        where = f"{self.map.source}: command {mapped.command.name!r}"
        if not mapped.action:
            return _Resolved()
        node = await self._node(client, mapped.node, where, mapped.action)
        want = ua.NodeClass.Method if mapped.action == "method" else ua.NodeClass.Variable
        if (cls := await node.read_node_class()) != want:
            raise DeviceError(f"{where}: {mapped.node} is a {cls.name}, not a {want.name}")
        if mapped.action == "method":
            if mapped.object:
                obj = await self._node(client, mapped.object, where, "object")
            else:
                obj = await node.get_parent()
                if obj is None:
                    raise DeviceError(f"{where}: method {mapped.node} has no parent object; "
                                      "name one with object = …")
            return _Resolved(node, obj)
        declared = (mapped.command.input_data_type if mapped.action == "write"
                    else mapped.command.output_data_type)
        assert declared is not None
        expected = _DATATYPE_IDS[VARIANT_TYPES[declared]]
        actual = await node.read_data_type()
        if actual != expected:
            raise DeviceError(
                f"{where}: variable {mapped.node} holds {actual.to_string()}, but the map "
                f"declares {declared.value} ({expected.to_string()})")
        return _Resolved(node)

    async def _node(self, client: Client, text: str, where: str, what: str) -> Node:
        """The node of a map's node id text (``nsu=`` resolved on this server)."""
        resolved = text
        if text.startswith("nsu="):
            uri, _, rest = text[4:].partition(";")
            try:
                idx = await client.get_namespace_index(uri)
            except ValueError:
                raise DeviceError(f"{where}: {what} {text}: the server has no namespace "
                                  f"{uri}") from None
            resolved = f"ns={idx};{rest}"
        node = client.get_node(ua.NodeId.from_string(resolved))
        try:
            await node.read_browse_name()
        except ua.UaStatusCodeError as exc:
            raise DeviceError(f"{where}: {what} {text} does not exist on {self.endpoint} "
                              f"({type(exc).__name__})") from None
        return node

    # -- the device interface ----------------------------------------------------------

    async def dispatch(self, command: Command, option: str, data: Any) -> str:
        mapped = self.map.command(command.name)
        if self._lost or self.client is None:
            raise DeviceError(self._lost or f"not connected to {self.endpoint}")
        nodes = self._nodes[command.name]
        try:
            match mapped.action:
                case "method":
                    assert nodes.object is not None and nodes.node is not None
                    args = [ua.Variant(option, ua.VariantType.String) if a == "option"
                            else _variant(data, command.input_data_type, command.input_data_size)
                            for a in mapped.arguments]
                    result = await nodes.object.call_method(nodes.node, *args)
                    if command.gives_output:
                        self.host.data_feedback.post(result[0] if isinstance(result, list)
                                                else result)
                case "write":
                    assert nodes.node is not None
                    await nodes.node.write_value(
                        _variant(data, command.input_data_type, command.input_data_size))
                case "read":
                    assert nodes.node is not None
                    self.host.data_feedback.post(await nodes.node.read_value())
                case "subscribe":
                    assert nodes.node is not None
                    await self._stop_stream()
                    self._subscription = await self.client.create_subscription(
                        mapped.interval_ms, _Stream(self))
                    await self._subscription.subscribe_data_change(nodes.node)
                case "":  # StopData: end the stream
                    await self._stop_stream()
        except ua.UaStatusCodeError as exc:
            raise DeviceError(f"the server answered {type(exc).__name__}: {exc}") from None
        except (TimeoutError, OSError, ConnectionError) as exc:
            raise DeviceError(f"connection to {self.endpoint}: {_why(exc)}") from None
        return command.success_code

    async def _stop_stream(self) -> None:
        subscription, self._subscription = self._subscription, None
        if subscription is not None and not self._lost:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(subscription.delete(), 5.0)


class _Stream:
    """asyncua's subscription handler: each value change is one DataFeedback."""

    def __init__(self, device: OpcUaDevice) -> None:
        self.device = device

    def datachange_notification(self, node: Node, value: Any, data: Any) -> None:
        if self.device._subscription is not None:
            self.device.host.data_feedback.post(value)


def _variant(data: Any, data_type: DataTypes | None, size: tuple[int, ...]) -> ua.Variant:
    """Checked input data (numpy) as the variant an OPC UA method or variable takes."""
    assert data_type is not None
    vtype = VARIANT_TYPES[data_type]
    arr = np.asarray(data)
    if size == (1,):
        value = arr.reshape(-1)[0]
        return ua.Variant(value if data_type is DataTypes.String else value.item(), vtype)
    dims = list(arr.shape) if arr.ndim > 1 else None
    return ua.Variant(arr.reshape(-1).tolist(), vtype, dims, is_array=True)


async def _cancellable(connect: Coroutine[Any, Any, None]) -> None:
    """Await ``connect`` so that cancelling the caller always works.

    asyncua opens the socket with ``asyncio.wait_for``, which before Python 3.12 swallows
    a cancellation that comes as the connection opens (cpython #86296): the connect then
    goes on to wait for the server's answer until its timeout — SIGTERM to a device
    service connecting to a silent server waited that long.  Here the caller waits on
    its own; on cancellation the connect is cancelled and left to end by itself.
    """
    task = asyncio.ensure_future(connect)
    try:
        await asyncio.wait({task})
    except asyncio.CancelledError:
        task.cancel()
        task.add_done_callback(lambda t: t.cancelled() or t.exception())
        raise
    task.result()


def _why(exc: BaseException) -> str:
    return str(exc) or type(exc).__name__
