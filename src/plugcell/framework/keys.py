"""The Zenoh key space of a cell (docs/protocol.md, "Key space").

Every key starts with ``plugcell/<cell>/`` so that several cells can share one
network without seeing each other.  Per service ``<name>``:

=====================================  ==========  ==========================================
key                                    Zenoh       message
=====================================  ==========  ==========================================
``live/service/<name>/<instance>``     liveliness  presence of a service incarnation
``live/client/<name>/<instance>``      liveliness  presence of a client (CLI, script, test)
``svc/<name>/get``                     queryable   Get → GenericDeviceState (Table 5-1)
``svc/<name>/create``                  queryable   CreateProcess(Process) → Acknowledgement
``svc/<name>/create/<sender>``         pub/sub     CreateProcess(Process) → Acknowledgement
                                                   on ``process/<sender>``
``svc/<name>/subscribe``               queryable   Subscribe/UnsubscribeRequest → Response
``svc/<name>/process/<sender>``        pub/sub     ProcessUpdate for processes of <sender>
``svc/<name>/state``                   pub/sub     StateUpdate
``svc/<name>/connection``              pub/sub     ConnectionUpdate
``svc/<name>/shutdown``                pub/sub     Shutdown
``joints/<name>``                      pub/sub     a robot service's joint state (a display
                                                   stream, several times a second)
``tracking/<name>``                    pub/sub     a robot service's tracked move as it goes
                                                   (a display stream, ≤ 10 batches a second)
=====================================  ==========  ==========================================
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Literal

ROOT = "plugcell"
DEFAULT_CELL = "default"
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]{0,63}$")

Role = Literal["service", "client"]


def check_name(name: str, what: str = "name") -> str:
    """Return ``name`` if it can be one chunk of a key, else raise ValueError."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise ValueError(
            f"invalid {what} {name!r}: use 1-64 letters, digits, '_', '.', '-' "
            "(starting with a letter or digit)"
        )
    return name


@dataclass(frozen=True)
class Presence:
    """One liveliness token, parsed: who is (or was) alive."""

    role: Role
    name: str
    instance: str


@dataclass(frozen=True)
class KeySpace:
    """All keys of one cell."""

    cell: str = DEFAULT_CELL

    def __post_init__(self) -> None:
        check_name(self.cell, "cell name")

    @property
    def prefix(self) -> str:
        return f"{ROOT}/{self.cell}"

    # presence (liveliness tokens)
    def live(self, role: Role, name: str, instance: str) -> str:
        return f"{self.prefix}/live/{role}/{name}/{instance}"

    def live_all(self) -> str:
        return f"{self.prefix}/live/**"

    def live_services(self, name: str = "*") -> str:
        return f"{self.prefix}/live/service/{name}/*"

    def parse_live(self, key: str) -> Presence | None:
        """The presence a liveliness key announces, or None if it is not one of ours."""
        parts = key.split("/")
        if len(parts) != 6 or parts[:3] != [ROOT, self.cell, "live"]:
            return None
        role = parts[3]
        if role not in ("service", "client"):
            return None
        return Presence(role, parts[4], parts[5])  # type: ignore[arg-type]

    # queryables of a service
    def get(self, name: str) -> str:
        return f"{self.prefix}/svc/{name}/get"

    def create(self, name: str) -> str:
        return f"{self.prefix}/svc/{name}/create"

    def request(self, name: str, sender: str) -> str:
        """Where ``sender`` publishes its CreateProcess requests to service ``name``."""
        return f"{self.prefix}/svc/{name}/create/{sender}"

    def requests(self, name: str) -> str:
        """Every CreateProcess published to service ``name``."""
        return f"{self.prefix}/svc/{name}/create/*"

    def request_sender(self, key: str) -> str:
        """The sender named by a :meth:`request` key (its last segment, unchecked)."""
        return key.rsplit("/", 1)[-1]

    def subscribe(self, name: str) -> str:
        return f"{self.prefix}/svc/{name}/subscribe"

    # notifications of a service
    def process(self, name: str, sender: str) -> str:
        return f"{self.prefix}/svc/{name}/process/{sender}"

    def process_for(self, sender: str) -> str:
        """All ProcessUpdates addressed to ``sender``, from any service."""
        return f"{self.prefix}/svc/*/process/{sender}"

    def all_processes(self) -> str:
        """Every ProcessUpdate of the cell (for a cell controller's monitor, 7.6)."""
        return f"{self.prefix}/svc/*/process/*"

    # the simulated cell (sim/world.py): the true pose of each reflector
    def reflector(self, name: str = "*") -> str:
        """Pub/sub and queryable of reflector ``name``'s true pose (``*``: every one)."""
        return f"{self.prefix}/sim/reflector/{name}"

    # a robot's joint state (devices/robot/joint_state.py): outside ``svc/<name>/*`` so
    # that a partner following a robot's notifications does not hear it
    def joints(self, name: str = "*") -> str:
        """Pub/sub of robot service ``name``'s joint state (``*``: every robot)."""
        return f"{self.prefix}/joints/{name}"

    def parse_joints(self, key: str) -> str | None:
        """The robot service a :meth:`joints` key of this cell names, else None."""
        return self._parse_robot_stream(key, "joints")

    # a robot's tracked move as it goes (devices/robot/live_tracking.py), beside its joints
    def tracking(self, name: str = "*") -> str:
        """Pub/sub of robot service ``name``'s live tracked move (``*``: every robot)."""
        return f"{self.prefix}/tracking/{name}"

    def parse_tracking(self, key: str) -> str | None:
        """The robot service a :meth:`tracking` key of this cell names, else None."""
        return self._parse_robot_stream(key, "tracking")

    def _parse_robot_stream(self, key: str, kind: str) -> str | None:
        parts = key.split("/")
        if len(parts) != 4 or parts[:3] != [ROOT, self.cell, kind]:
            return None
        return parts[3]

    def parse_process(self, key: str) -> tuple[str, str] | None:
        """``(service, sender)`` of a :meth:`process` key of this cell, else None."""
        parts = key.split("/")
        if len(parts) != 6 or parts[:3] != [ROOT, self.cell, "svc"] or parts[4] != "process":
            return None
        return parts[3], parts[5]

    def state(self, name: str) -> str:
        return f"{self.prefix}/svc/{name}/state"

    def connection(self, name: str) -> str:
        return f"{self.prefix}/svc/{name}/connection"

    def shutdown(self, name: str) -> str:
        return f"{self.prefix}/svc/{name}/shutdown"

    def notifications(self, name: str) -> str:
        """State, connection and shutdown notifications of ``name`` (one wildcard)."""
        return f"{self.prefix}/svc/{name}/*"
