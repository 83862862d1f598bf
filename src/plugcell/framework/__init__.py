"""plugcell.framework — Plug-and-Produce services over Zenoh (thesis ch. 4.1, 5, appendix F).

Modules, one job each:

* :mod:`.model` — the predefined classes and enumerations (appendix F);
* :mod:`.data` — typed data buffers and their checks against a command (F.4, F.5);
* :mod:`.codec` — the versioned MessagePack envelope (docs/protocol.md);
* :mod:`.keys` — the Zenoh key space of a cell;
* :mod:`.transport` — Zenoh sessions (peer on loopback, or via a router);
* :mod:`.port` — the CCR Port between Zenoh callbacks and the event loop (E.1);
* :mod:`.processqueue` — the FIFO process queue with re-scheduling (5.2.3.5);
* :mod:`.journal` — the journal of every process and update (SQLite, fed by
  :mod:`.journal_log`, the append-only log each commit writes);
* :mod:`.participant` — presence, partners; :mod:`.calls` — its outbound processes
  (5.2.3.6);
* :mod:`.process_call` — a process as its sender sees it;
* :mod:`.declaration` — what a device declares (kind, names, command catalogue);
* :mod:`.service` — GenericDevice, the service that hosts one device (5.2.2–5.2.3), with
  :mod:`.inbound` (its doors Subscribe and CreateProcess, admitted);
* :mod:`.client` — the async and blocking client API.
"""

from plugcell.framework.client import BlockingClient, BlockingProcessCall, Client
from plugcell.framework.data import DataError, from_data, to_data
from plugcell.framework.keys import DEFAULT_CELL, KeySpace
from plugcell.framework.messages import (
    Acknowledgement,
    Command,
    CommandTypes,
    ConnectionStates,
    Data,
    DataTypes,
    Device,
    DeviceStates,
    GenericDeviceState,
    Process,
    ProcessStates,
    ProcessUpdateBatch,
    ProcessUpdateNotification,
    Tag,
)
from plugcell.framework.participant import Participant, PartnerError
from plugcell.framework.process_call import ProcessCall
from plugcell.framework.service import DeviceError, GenericDevice
from plugcell.framework.transport import TransportConfig

__all__ = [
    "DEFAULT_CELL",
    "Acknowledgement",
    "BlockingClient",
    "BlockingProcessCall",
    "Client",
    "Command",
    "CommandTypes",
    "ConnectionStates",
    "Data",
    "DataError",
    "DataTypes",
    "Device",
    "DeviceError",
    "DeviceStates",
    "GenericDevice",
    "GenericDeviceState",
    "KeySpace",
    "Participant",
    "PartnerError",
    "Process",
    "ProcessCall",
    "ProcessStates",
    "ProcessUpdateBatch",
    "ProcessUpdateNotification",
    "Tag",
    "TransportConfig",
    "from_data",
    "to_data",
]
