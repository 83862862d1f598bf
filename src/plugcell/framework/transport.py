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
(``0`` to disable shared memory), ``PLUGCELL_LEASE`` (seconds a silent link is
trusted; Zenoh's 10 s by default), ``PLUGCELL_MODE`` (``client``: one link to a
router instead of one to every other process — a star instead of a mesh; the router is
found by ``PLUGCELL_CONNECT`` or, on the host, by scouting).

What an idle cell costs is mostly these settings (docs/results/framework-performance.md,
"An idle cell"): shared memory wakes each process ten times a second (zenoh-transport's
shared-memory hand-off task, once a link has negotiated it), and each link sends keep-alives every
quarter lease — in a mesh of N processes N(N−1)/2 links, through a router N.

Security (docs/security.md): ``PLUGCELL_TLS_CA``, ``PLUGCELL_TLS_CERT``,
``PLUGCELL_TLS_KEY`` (PEM files from ``plugcell certs``) switch the links to TLS with
mutual authentication (``PLUGCELL_MTLS=0`` for server-side only);
``PLUGCELL_TLS_DIR`` + a participant name stand for ``DIR/ca.pem``,
``DIR/<name>.pem``, ``DIR/<name>.key`` (:meth:`TransportConfig.for_participant`).
``PLUGCELL_CELL_NAMES`` (the certificates' CNs) adds Zenoh access control so that
no peer can speak as another.
A participant with a certificate and key also signs its requests
(:mod:`~plugcell.framework.signing`; ``PLUGCELL_SIGN=0`` to stop).
``PLUGCELL_USER``, ``PLUGCELL_PASSWORD`` and ``PLUGCELL_USERS_FILE`` add Zenoh's
user/password authentication.  With neither, the embedded default is unchanged.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import zenoh

from plugcell.framework.security import tls_settings, usrpwd_settings, zenoh_acl

LOOPBACK_LISTEN = ("tcp/127.0.0.1:0",)
#: Zenoh's own default lease (transport/link/tx/lease), seconds.
ZENOH_LEASE_S = 10.0
ROUTER_LISTEN = ("tcp/0.0.0.0:7447",)
#: The modes a participant may join in (``PLUGCELL_MODE``); ``plugcell router`` runs
#: the third, "router".
PARTICIPANT_MODES = ("peer", "client")


def parse_lease(text: str, what: str = "lease") -> float:
    """A lease in seconds from ``text``: a number in [1, 3600] (ValueError with why)."""
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{what} must be a number of seconds, got {text!r}") from None
    if not 1.0 <= value <= 3600.0:
        raise ValueError(f"{what} must be between 1 and 3600 s, got {text}")
    return value


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
    lease_s: float = ZENOH_LEASE_S
    """How long a link may stay silent before Zenoh declares its peer gone; keep-alives
    go every quarter of it on every link (an idle cost — docs/results/framework-performance.md,
    "An idle cell").  A process that dies closes its links at once whatever the lease; the lease
    bounds the detection of a peer that hangs or a network that breaks."""
    extra: dict[str, object] = field(default_factory=dict)
    """Further Zenoh configuration, ``{"json/path": value}`` (inserted as JSON5)."""
    tls_ca: str = ""
    """Cell CA certificate (PEM); set → TLS links only (docs/security.md)."""
    tls_cert: str = ""
    """This participant's certificate (PEM, CN = its name)."""
    tls_key: str = ""
    """Its private key (PEM)."""
    mtls: bool = True
    """Demand a certificate from every connecting peer (mutual TLS)."""
    tls_dir: str = ""
    """Folder of ``ca.pem``, ``<name>.pem``, ``<name>.key`` (see :meth:`for_participant`)."""
    username: str = ""
    password: str = ""
    users_file: str = ""
    """``user:password`` lines a listener accepts (Zenoh usrpwd authentication)."""
    cell_names: tuple[str, ...] = ()
    """With TLS: the cell's certificate CNs → Zenoh ACL against impersonation
    (:func:`~plugcell.framework.security.zenoh_acl`)."""
    sign_requests: bool = True
    """With a certificate and key: sign every request (:mod:`~plugcell.framework.signing`;
    ``PLUGCELL_SIGN=0`` turns it off)."""

    @property
    def secure(self) -> bool:
        """True when the links are TLS."""
        return bool(self.tls_ca)

    def for_participant(self, name: str) -> TransportConfig:
        """Fill the certificate of participant ``name`` from :attr:`tls_dir` if unset."""
        if not self.tls_dir or (self.tls_ca and self.tls_cert):
            return self
        folder = os.path.abspath(self.tls_dir)
        if not self.tls_cert and not os.path.isfile(os.path.join(folder, f"{name}.pem")):
            raise ValueError(
                f"no certificate for {name} in {folder}: "
                f"run `plugcell certs issue {name} --dir {self.tls_dir}`"
            )
        return replace(
            self,
            tls_ca=self.tls_ca or os.path.join(folder, "ca.pem"),
            tls_cert=self.tls_cert or os.path.join(folder, f"{name}.pem"),
            tls_key=self.tls_key or os.path.join(folder, f"{name}.key"),
        )

    @classmethod
    def from_env(
        cls,
        connect: Sequence[str] | None = None,
        listen: Sequence[str] | None = None,
        mode: str | None = None,
    ) -> TransportConfig:
        """Defaults, then the ``PLUGCELL_*`` environment, then explicit arguments.

        ``mode`` None takes ``PLUGCELL_MODE`` (``peer`` unless set).  A client listens on
        nothing and needs a router to reach: ``connect`` endpoints or multicast scouting
        (ValueError otherwise, and for a mode that is neither peer nor client, or a
        client given endpoints to listen on).
        """
        if mode is None:
            mode = os.environ.get("PLUGCELL_MODE", "").strip() or "peer"
            if mode not in PARTICIPANT_MODES:
                raise ValueError(f"PLUGCELL_MODE must be peer or client, got {mode!r}")
        listen_default = {"router": ROUTER_LISTEN, "client": ()}.get(mode, LOOPBACK_LISTEN)
        cfg = cls(mode=mode, listen=listen_default)
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
        lease = os.environ.get("PLUGCELL_LEASE")
        if lease:
            cfg = replace(cfg, lease_s=parse_lease(lease, "PLUGCELL_LEASE"))
        cfg = _security_from_env(cfg)
        if connect:
            cfg = replace(cfg, connect=tuple(connect))
        if listen:
            cfg = replace(cfg, listen=tuple(listen))
        if mode == "client":
            if cfg.listen:
                raise ValueError("a client listens on nothing: it reaches the cell through "
                                 "a router (unset PLUGCELL_LISTEN and --listen)")
            if not cfg.connect and not cfg.multicast:
                raise ValueError("a client needs a router to reach: PLUGCELL_CONNECT (or "
                                 "--connect) or multicast scouting")
        if cfg.tls_ca:  # a TLS cell listens on TLS only
            cfg = replace(cfg, listen=tuple(_to_tls(e) for e in cfg.listen))
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
        if self.lease_s != ZENOH_LEASE_S:
            conf.insert_json5("transport/link/tx/lease", json.dumps(round(self.lease_s * 1000)))
        for path, value in self._security_settings().items():
            conf.insert_json5(path, json.dumps(value))
        for path, value in self.extra.items():
            conf.insert_json5(path, json.dumps(value))
        return conf

    def _security_settings(self) -> dict[str, object]:
        settings: dict[str, object] = {}
        if self.tls_ca:
            settings.update(tls_settings(self.tls_ca, self.tls_cert, self.tls_key, self.mtls))
            if self.cell_names:
                settings["access_control"] = zenoh_acl(self.cell_names)
        settings.update(usrpwd_settings(self.username, self.password, self.users_file))
        return settings


def _security_from_env(cfg: TransportConfig) -> TransportConfig:
    """Apply ``PLUGCELL_TLS_*``, ``PLUGCELL_MTLS``, ``PLUGCELL_USER``… to ``cfg``."""
    env = os.environ
    changes: dict[str, object] = {
        attr: env[var].strip()
        for attr, var in (
            ("tls_ca", "PLUGCELL_TLS_CA"),
            ("tls_cert", "PLUGCELL_TLS_CERT"),
            ("tls_key", "PLUGCELL_TLS_KEY"),
            ("tls_dir", "PLUGCELL_TLS_DIR"),
            ("username", "PLUGCELL_USER"),
            ("password", "PLUGCELL_PASSWORD"),
            ("users_file", "PLUGCELL_USERS_FILE"),
        )
        if env.get(var, "").strip()
    }
    if _split(env.get("PLUGCELL_CELL_NAMES")):
        changes["cell_names"] = _split(env.get("PLUGCELL_CELL_NAMES"))
    if env.get("PLUGCELL_MTLS", "1") in ("0", "false", "no"):
        changes["mtls"] = False
    if env.get("PLUGCELL_SIGN", "1") in ("0", "false", "no"):
        changes["sign_requests"] = False
    if changes.get("tls_dir") and not changes.get("tls_ca"):
        changes["tls_ca"] = os.path.join(os.path.abspath(str(changes["tls_dir"])), "ca.pem")
    return replace(cfg, **changes)  # type: ignore[arg-type]


def _to_tls(endpoint: str) -> str:
    """``tcp/HOST:PORT`` → ``tls/HOST:PORT`` (a TLS cell listens on TLS only)."""
    return "tls/" + endpoint[4:] if endpoint.startswith("tcp/") else endpoint


class NoRouterError(ConnectionError):
    """A client (``PLUGCELL_MODE=client``) reached no router; the message says where it
    looked."""


def open_session(config: TransportConfig | None = None) -> zenoh.Session:
    """Open a Zenoh session (blocks up to Zenoh's scouting delay, ~0.5 s when alone).

    Raises :class:`NoRouterError` when a client reaches no router (a peer needs nobody).
    """
    config = config or TransportConfig.from_env()
    try:
        return zenoh.open(config.zenoh_config())
    except zenoh.ZError as exc:
        if config.mode != "client":
            raise
        where = (", ".join(config.connect) if config.connect
                 else f"scouting on {config.multicast_interface}")
        raise NoRouterError(
            f"no router reached ({where}): a client (PLUGCELL_MODE=client) joins the cell "
            f"through a running `plugcell router`; Zenoh: {exc}") from None
