"""The predefined classes and enumerations of the framework (thesis 5.2.1, appendix F).

Every structure is a :class:`msgspec.Struct`: typed, validated when decoded, and
serialised to MessagePack with the thesis's own member names (``Name``,
``SuccessCode``, ``InputDataSize`` …, ``rename="pascal"``) so that the wire schema
reads like tables F-5 … F-13.  Python attributes are the same names in
snake_case.

Extensions beyond appendix F are marked *plugcell extension* and always have a
default, so a peer that does not know them can leave them out.
"""

from __future__ import annotations

import enum
from datetime import UTC, datetime
from typing import Annotated

import msgspec

#: Largest process identifier: identifiers are stored as signed 64-bit integers.
MAX_IDENTIFIER = 2**63 - 1
#: Largest rank of an n-D data size (F.5 e).
MAX_RANK = 8

Name = Annotated[str, msgspec.Meta(pattern=r"^[A-Za-z0-9][A-Za-z0-9_.\-]{0,63}$")]
"""A service or cell name: it becomes one chunk of a Zenoh key."""
CommandName = Annotated[str, msgspec.Meta(min_length=1, max_length=64)]
Dim = Annotated[int, msgspec.Meta(ge=-1, le=2**31 - 1)]
"""One declared dimension; ``-1`` (plugcell extension) means *any length*."""
DeclaredSize = Annotated[tuple[Dim, ...], msgspec.Meta(max_length=MAX_RANK)]
Identifier = Annotated[int, msgspec.Meta(ge=1, le=MAX_IDENTIFIER)]


class DeviceStates(enum.Enum):
    """Table F-1: the status of the device."""

    Ready = "Ready"
    Busy = "Busy"
    Error = "Error"


class ConnectionStates(enum.Enum):
    """Table F-2: the connection between the service and its device controller."""

    Online = "Online"
    Offline = "Offline"
    Error = "Error"


class CommandTypes(enum.Enum):
    """Table F-3 and 5.2.1.1 (a)–(d): the four generic kinds of command."""

    NoData = "NoData"
    SingleData = "SingleData"
    MultipleData = "MultipleData"
    StopData = "StopData"


class DataTypes(enum.Enum):
    """Table F-4: the element type of command input/output data."""

    Boolean = "Boolean"
    Byte = "Byte"
    Integer = "Integer"
    Double = "Double"
    String = "String"


class ProcessStates(enum.Enum):
    """Table F-8: the status of a process."""

    Queued = "Queued"
    Running = "Running"
    Completed = "Completed"
    Failed = "Failed"

    final: bool
    """True for the two states that end a process (Completed, Failed)."""


for _state in ProcessStates:
    _state.final = _state in (ProcessStates.Completed, ProcessStates.Failed)


class Command(msgspec.Struct, rename="pascal", frozen=True, kw_only=True):
    """Table F-5: a control command of a device, as listed in its catalogue.

    Sizes follow F.5: ``(0,)`` no data, ``(1,)`` a scalar, ``(n,)`` a vector,
    ``(m, n)`` a matrix (m rows), ``(m1, …, mn)`` an n-D array.  plugcell
    extensions: ``-1`` in a size means *any length in that dimension*, an empty
    size ``()`` means *any shape*; ``timeout`` bounds the wait for the device's
    command feedback, and for a MultipleData command the whole time it may hold
    the device; ``info`` describes the command for people.
    """

    name: CommandName
    option: str = ""
    success_code: str = "OK"
    type: CommandTypes = CommandTypes.NoData
    input_data_type: DataTypes | None = None
    input_data_size: DeclaredSize = (0,)
    output_data_type: DataTypes | None = None
    output_data_size: DeclaredSize = (0,)
    timeout: Annotated[float, msgspec.Meta(gt=0, le=86400 * 365)] = 10.0
    info: str = ""

    @property
    def takes_input(self) -> bool:
        """Whether the command expects input data (F.5 a: size ``(0,)`` means none)."""
        return self.input_data_size != (0,)

    @property
    def gives_output(self) -> bool:
        """Whether the command returns data (SingleData/MultipleData with a size)."""
        return self.output_data_size != (0,) and self.type in (
            CommandTypes.SingleData,
            CommandTypes.MultipleData,
        )


class Data(msgspec.Struct, rename="pascal", frozen=True):
    """Input/output data of a process as a typed buffer (the generic ``Object`` of F.9/F.10).

    ``buffer`` holds the elements in C (row-major) order: little-endian
    ``int32`` for Integer, ``float64`` for Double, one byte per element for Byte
    and Boolean (0/1); for String it is the array of UTF-8 strings.  ``size`` is
    the actual n-D shape (no ``-1``).

    A numeric ``buffer`` is any bytes-like object: ``bytes``, or a read-only
    ``memoryview`` of unsigned bytes — a decoded message's buffers are views into the
    received payload (no copy; each keeps the whole payload alive while it is
    referenced), and :func:`~plugcell.framework.data.to_data` of a read-only array is a
    view of that array.  Both encode to the same MessagePack ``bin``.
    """

    type: DataTypes
    size: Annotated[
        tuple[Annotated[int, msgspec.Meta(ge=0)], ...], msgspec.Meta(max_length=MAX_RANK)
    ]
    buffer: memoryview | list[str]


class Device(msgspec.Struct, rename="pascal", kw_only=True):
    """Table F-6: information about the device a service represents.

    plugcell extension: ``kind`` names the service implementation (camera, drill …).
    """

    name: Name
    vendor: str = ""
    info: str = ""
    connection: ConnectionStates = ConnectionStates.Offline
    state: DeviceStates = DeviceStates.Ready
    commands: tuple[Command, ...] = ()
    last_updated: datetime = msgspec.field(default_factory=lambda: datetime.now(UTC))
    kind: str = ""

    def command(self, name: str) -> Command | None:
        """The catalogue entry called ``name``, or None."""
        for command in self.commands:
            if command.name == name:
                return command
        return None


class Tag(msgspec.Struct, rename="pascal", frozen=True):
    """Table F-7: names of the sender and the recipient of a request."""

    sender: Name
    recipient: Name


class _Message(msgspec.Struct, rename="pascal", tag_field="Kind", tag=True, kw_only=True):
    """Base of every message body: its MessagePack map carries ``"Kind": <class name>``."""


class GetRequest(_Message):
    """The ``Get`` operation (Table 5-2): asks for the whole generic state."""


class GenericDeviceState(_Message):
    """Table 5-1: the generic state every service has, answered to ``Get``."""

    device_info: Device
    partners: list[Device] = []


class Process(_Message):
    """Table F-9: the dynamic instance of a command; the body of ``CreateProcess``.

    The recipient trusts only ``command.name`` and ``command.option`` and uses its
    own catalogue for the rest.  ``identifier`` is chosen by the sender and is
    unique per sender.
    """

    command: Command
    tag: Tag
    identifier: Identifier
    state: ProcessStates = ProcessStates.Queued
    data: Data | None = None


class Acknowledgement(_Message):
    """The response to ``CreateProcess`` (5.2.3.4: "send an acknowledgement receipt").

    plugcell extension: a rejected request is acknowledged ``Failed`` with its
    ``reason``; ``instance`` identifies the incarnation of the recipient that
    accepted the process (it ends Failed if that incarnation dies).
    """

    identifier: int
    state: ProcessStates
    reason: str = ""
    instance: str = ""


class ProcessUpdateNotification(_Message):
    """Table F-10: body of the ``ProcessUpdate`` notification.

    plugcell extensions: ``reason`` says why a process Failed; ``seq`` numbers the
    updates of one process from 1 so a receiver can see a gap.
    """

    tag: Tag
    identifier: int
    state: ProcessStates
    data: Data | None = None
    reason: str = ""
    seq: int = 0


class ProcessUpdateBatch(_Message):
    """Acknowledgements and ProcessUpdates of one service for one sender, in order.

    plugcell extension (docs/protocol.md, "Batches"): what a service produces for
    one sender in one turn of its loop travels in one Zenoh sample — the
    acknowledgements of the requests that sender published, then the updates — so
    a request and its first updates cost one transport message, and a stream of
    small frames one per burst instead of one per frame.  A receiver treats it
    exactly as its ``acks`` and then its ``updates`` arriving one after another.
    """

    acks: list[Acknowledgement] = msgspec.field(default_factory=list)
    updates: list[ProcessUpdateNotification] = msgspec.field(default_factory=list)


class StateUpdateNotification(_Message):
    """Table F-12: body of the ``StateUpdate`` notification."""

    name: Name
    state: DeviceStates


class ConnectionUpdateNotification(_Message):
    """Table F-11: body of the ``ConnectionUpdate`` notification."""

    name: Name
    connection: ConnectionStates


class ShutdownNotification(_Message):
    """Table F-13: body of the ``Shutdown`` notification (plugcell extension: ``reason``)."""

    name: Name
    reason: str = ""


class SubscribeRequest(_Message):
    """``Subscribe(partner)`` of 4.1.3.1 sent to a service: make it subscribe to ``partner``."""

    partner: Name


class UnsubscribeRequest(_Message):
    """Make a service drop ``partner`` from its Partners (the array shrinks by one, 4.1.3.1)."""

    partner: Name


class SubscribeResponse(_Message):
    """The answer to Subscribe/Unsubscribe: the partner's DeviceInfo, or why not."""

    ok: bool
    reason: str = ""
    partner: Device | None = None


Message = (
    Process
    | Acknowledgement
    | ProcessUpdateNotification
    | ProcessUpdateBatch
    | StateUpdateNotification
    | ConnectionUpdateNotification
    | ShutdownNotification
    | GetRequest
    | GenericDeviceState
    | SubscribeRequest
    | UnsubscribeRequest
    | SubscribeResponse
)
"""Every message body; the MessagePack map carries its class name under ``"Kind"``."""


def process_updates(body: Message) -> list[ProcessUpdateNotification]:
    """The ProcessUpdates a notification carries, in order: one, a batch's, or none."""
    if isinstance(body, ProcessUpdateNotification):
        return [body]
    if isinstance(body, ProcessUpdateBatch):
        return body.updates
    return []


def process_acks(body: Message) -> list[Acknowledgement]:
    """The Acknowledgements a notification on a process key carries: one, a batch's, none."""
    if isinstance(body, Acknowledgement):
        return [body]
    if isinstance(body, ProcessUpdateBatch):
        return body.acks
    return []
