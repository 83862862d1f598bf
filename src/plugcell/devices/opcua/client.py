"""The asyncua client behind the OPC UA device service: :class:`AsyncuaDriver`.

The :class:`~plugcell.devices.opcua.driver.OpcUaDriver` that ``plugcell serve
opcua-device`` gives the service: a session with the server at ``endpoint`` —
Basic256Sha256 SignAndEncrypt with the cell's certificate of the service
(``--param certs=DIR``, ``plugcell certs opcua NAME``) and the server's certificate
checked (:mod:`plugcell.devices.opcua.server_trust`), or, on a test bench only,
SecurityPolicy None with any server (``--insecure-accept-any``) — and the OPC UA
services the device needs, each an asyncua call.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
from collections.abc import Callable, Coroutine, Iterator, Sequence
from pathlib import Path
from typing import Any, ClassVar

from asyncua import Client, Node, ua
from asyncua.common.methods import call_method_full

from plugcell.devices.opcua.arguments import VARIANT_TYPES
from plugcell.devices.opcua.driver import OpcUaDriverError, OpcUaStatusError, OpcUaValue
from plugcell.devices.opcua.server_trust import ServerTrust
from plugcell.devices.params import flag
from plugcell.framework.service import DeviceError

log = logging.getLogger("plugcell.devices.opcua.device")
if logging.getLogger("asyncua").level == logging.NOTSET:
    # asyncua warns of things nobody can act on (revised session timeouts …); its
    # errors still show (a program that wants its warnings sets the level before)
    logging.getLogger("asyncua").setLevel(logging.ERROR)

__all__ = ["AsyncuaDriver"]


class AsyncuaDriver:
    """An asyncua client of one OPC UA server (module docstring).

    Parameters
    ----------
    endpoint : str
        The server, ``opc.tcp://HOST:PORT[/PATH]``.
    certs : str or Path
        The cell's certificate folder: connect with Basic256Sha256 SignAndEncrypt as
        ``<certs>/<name>.opcua.pem`` ("": only with ``insecure_accept_any``).
    user : str
        OPC UA user name; its password is ``$PLUGCELL_OPCUA_PASSWORD`` ("": anonymous).
    trust : str or Path
        A folder of trusted certificates (pinned servers, authorities) and revocation
        lists, beside the cell's CA.
    server_uri : str
        The application URI the server must have ("": the one it says it has).
    insecure_accept_any : bool
        Accept any server, its certificate unchecked (a test bench only; logged).

    Raises
    ------
    ValueError
        No endpoint; neither a certificate folder nor ``insecure_accept_any``; a trust
        folder or server URI without a certificate folder (only a secured connection
        has a server certificate to check).
    """

    params: ClassVar[dict[str, Any]] = {
        "endpoint": str, "certs": str, "user": str, "trust": str, "server_uri": str,
        "insecure_accept_any": flag,
    }

    def __init__(
        self,
        *,
        endpoint: str = "",
        certs: str | Path = "",
        user: str = "",
        trust: str | Path = "",
        server_uri: str = "",
        insecure_accept_any: bool = False,
    ) -> None:
        if not endpoint:
            raise ValueError("opcua-device needs --endpoint opc.tcp://HOST:PORT")
        if not certs and not insecure_accept_any:
            raise ValueError(
                f"opcua-device cannot authenticate the server of {endpoint} without a "
                "certificate of its own: give --param certs=DIR (SecurityPolicy Basic256Sha256, "
                "the server's certificate checked against the cell's CA and --trust DIR), or, "
                "on a test bench only, --insecure-accept-any (SecurityPolicy None, any server)")
        if (trust or server_uri) and not certs:
            raise ValueError("--trust and server_uri check the server's certificate, which only "
                             "a secured connection has: give --param certs=DIR too")
        self.endpoint = endpoint
        self.certs = Path(certs) if certs else None
        self.user = user
        self.trust = Path(trust) if trust else None
        self.server_uri = server_uri
        self.insecure_accept_any = insecure_accept_any
        self.client: Client | None = None
        self._warned = False

    # -- the session -------------------------------------------------------------------

    async def connect(self, client_name: str, timeout_s: float) -> None:
        if self.insecure_accept_any and not self._warned:
            self._warned = True
            log.warning("%s: --insecure-accept-any: accepting whatever server answers at %s, "
                        "its certificate unchecked (a test bench only)", client_name,
                        self.endpoint)
        client = Client(self.endpoint, timeout=timeout_s)
        if self.user:
            client.set_user(self.user)
            client.set_password(os.environ.get("PLUGCELL_OPCUA_PASSWORD", ""))
        try:
            if self.certs is not None:
                await self._secure(client, self.certs, client_name)
            await _cancellable(client.connect())
        except DeviceError as exc:  # the server's certificate refused (server_trust)
            raise OpcUaDriverError(str(exc)) from None
        except ua.UaError as exc:
            raise OpcUaDriverError(_why(exc)) from None
        self.client = client

    async def _secure(self, client: Client, folder: Path, name: str) -> None:
        """Basic256Sha256 SignAndEncrypt with the application certificate of ``name``."""
        from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
        from asyncua.crypto.uacrypto import CertProperties

        from plugcell.devices.opcua.certificates import application_uri, certificate_paths, uri_of

        cert, key = certificate_paths(folder, name)
        if not cert.is_file() or not key.is_file():
            raise OpcUaDriverError(f"no OPC UA certificate {cert}: run `plugcell certs opcua "
                                   f"{name} --dir {folder}`")
        client.application_uri = uri_of(cert) or application_uri(name)
        if not self.insecure_accept_any:  # read again at each connection: rotations
            client.certificate_validator = ServerTrust.load(
                self.endpoint, cell_certs=folder, trust=self.trust,
                expected_uri=self.server_uri)
        await client.set_security(
            SecurityPolicyBasic256Sha256, CertProperties(cert, "pem"), CertProperties(key, "pem"),
            mode=ua.MessageSecurityMode.SignAndEncrypt)

    async def disconnect(self) -> None:
        client, self.client = self.client, None
        if client is not None:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(client.disconnect(), 2.0)

    def _session(self) -> Client:
        if self.client is None:
            raise ConnectionError(f"no session with {self.endpoint}")
        return self.client

    async def server_state(self) -> int:
        state = self._session().get_node(ua.NodeId(ua.ObjectIds.Server_ServerStatus_State))
        return int(await state.read_value())

    async def namespace_index(self, uri: str) -> int:
        try:
            return await self._session().get_namespace_index(uri)
        except ValueError:
            raise KeyError(uri) from None

    # -- nodes -------------------------------------------------------------------------

    async def find(self, node_id: str) -> Node:
        node = self._session().get_node(ua.NodeId.from_string(node_id))
        with _status():
            await node.read_browse_name()
        return node

    async def node_class(self, node: Node) -> str:
        with _status():
            return (await node.read_node_class()).name

    async def data_type(self, node: Node) -> str:
        with _status():
            return (await node.read_data_type()).to_string()

    async def parent(self, node: Node) -> Node | None:
        with _status():
            return await node.get_parent()

    async def call(self, obj: Node, method: Node, arguments: Sequence[OpcUaValue]
                   ) -> list[Any]:
        with _status():
            result = await call_method_full(obj, method, *map(_variant, arguments))
        return list(result.OutputArguments)

    async def read(self, node: Node) -> Any:
        with _status():
            return await node.read_value()

    async def write(self, node: Node, value: OpcUaValue) -> None:
        with _status():
            await node.write_value(_variant(value))

    async def subscribe(self, node: Node, interval_ms: float,
                        on_value: Callable[[Any], None]) -> Any:
        with _status():
            subscription = await self._session().create_subscription(
                interval_ms, _Handler(on_value))
            await subscription.subscribe_data_change(node)
        return subscription


class _Handler:
    """asyncua's subscription handler: each value change to ``on_value``."""

    def __init__(self, on_value: Callable[[Any], None]) -> None:
        self.on_value = on_value

    def datachange_notification(self, node: Node, value: Any, data: Any) -> None:
        self.on_value(value)


@contextlib.contextmanager
def _status() -> Iterator[None]:
    """asyncua's Bad status exceptions as :class:`OpcUaStatusError` (its class name is the
    status code's)."""
    try:
        yield
    except ua.UaStatusCodeError as exc:
        raise OpcUaStatusError(str(exc), type(exc).__name__) from None


def _variant(value: OpcUaValue) -> ua.Variant:
    """``value`` as the variant of its data type (:data:`~.arguments.VARIANT_TYPES`)."""
    vtype = VARIANT_TYPES[value.data_type]
    if not value.is_array:
        return ua.Variant(value.value, vtype)
    return ua.Variant(value.value, vtype, list(value.dims) if value.dims else None,
                      is_array=True)


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
