"""Zenoh sessions for plugcell (design notes, "Transport").

Default: **peer mode on loopback**.  Each process listens on ``tcp/127.0.0.1``
with a port the OS chooses and finds the others by Zenoh multicast scouting
bound to the loopback interface (``127.0.0.1``), so nothing has to be started and
nothing leaves the host.  For a cell spanning machines, run ``plugcell router``
(the same library in router mode) and give every process ``--connect
tcp/<router>:7447`` (or ``PLUGCELL_CONNECT``).

Between processes of one host Zenoh moves messages of 3 KiB and more through
shared memory (its default "transport optimization"); ``shared_memory=False``
(``PLUGCELL_SHM=0``) forces every byte through the links — what a cell spanning
machines does anyway.

Environment: ``PLUGCELL_CONNECT`` and ``PLUGCELL_LISTEN`` (comma-separated
endpoints), ``PLUGCELL_MULTICAST`` (``0`` to disable scouting), ``PLUGCELL_SHM``
(``0`` to disable shared memory).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import zenoh

LOOPBACK_LISTEN = ("tcp/127.0.0.1:0",)
ROUTER_LISTEN = ("tcp/0.0.0.0:7447",)


def _split(value: str | None) -> tuple[str, ...]:
    return tuple(v.strip() for v in (value or "").split(",") if v.strip())


@dataclass(frozen=True)
class TransportConfig:
    """How a participant joins the Zenoh network."""

    mode: str = "peer"
    listen: tuple[str, ...] = LOOPBACK_LISTEN
    connect: tuple[str, ...] = ()
    multicast: bool = True
    multicast_interface: str = "127.0.0.1"
    shared_memory: bool = True
    extra: dict[str, object] = field(default_factory=dict)
    """Further Zenoh configuration, ``{"json/path": value}`` (inserted as JSON5)."""

    @classmethod
    def from_env(
        cls,
        connect: Sequence[str] | None = None,
        listen: Sequence[str] | None = None,
        mode: str = "peer",
    ) -> TransportConfig:
        """Defaults, then the ``PLUGCELL_*`` environment, then explicit arguments."""
        cfg = cls(mode=mode, listen=ROUTER_LISTEN if mode == "router" else LOOPBACK_LISTEN)
        env_connect = _split(os.environ.get("PLUGCELL_CONNECT"))
        env_listen = _split(os.environ.get("PLUGCELL_LISTEN"))
        if env_connect:
            cfg = replace(cfg, connect=env_connect)
        if env_listen:
            cfg = replace(cfg, listen=env_listen)
        if os.environ.get("PLUGCELL_MULTICAST", "1") in ("0", "false", "no"):
            cfg = replace(cfg, multicast=False)
        if os.environ.get("PLUGCELL_SHM", "1") in ("0", "false", "no"):
            cfg = replace(cfg, shared_memory=False)
        if connect:
            cfg = replace(cfg, connect=tuple(connect))
        if listen:
            cfg = replace(cfg, listen=tuple(listen))
        return cfg

    def zenoh_config(self) -> zenoh.Config:
        """The :class:`zenoh.Config` for this transport."""
        conf = zenoh.Config()
        conf.insert_json5("mode", json.dumps(self.mode))
        conf.insert_json5("listen/endpoints", json.dumps(list(self.listen)))
        conf.insert_json5("connect/endpoints", json.dumps(list(self.connect)))
        conf.insert_json5("scouting/multicast/enabled", json.dumps(self.multicast))
        if self.multicast:
            conf.insert_json5("scouting/multicast/interface", json.dumps(self.multicast_interface))
        if not self.shared_memory:
            conf.insert_json5("transport/shared_memory/enabled", "false")
        for path, value in self.extra.items():
            conf.insert_json5(path, json.dumps(value))
        return conf


def open_session(config: TransportConfig | None = None) -> zenoh.Session:
    """Open a Zenoh session (blocks up to Zenoh's scouting delay, ~0.5 s when alone)."""
    return zenoh.open((config or TransportConfig.from_env()).zenoh_config())
