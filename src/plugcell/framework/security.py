"""Security of a cell: TLS settings for Zenoh and the access policy of a service.

Two layers (docs/security.md):

* **Transport** — Zenoh TLS with mutual authentication: every participant holds a
  certificate issued by the cell's CA (``plugcell certs``) whose common name is its
  participant name; a peer without a certificate, or with one from another CA, never
  gets a link.  Optionally Zenoh user/password authentication on top.
  :func:`tls_settings` and :func:`usrpwd_settings` give the Zenoh configuration
  entries (checked against eclipse-zenoh 1.10.2); :class:`~.transport.TransportConfig`
  applies them.
* **Service** — an :class:`AccessPolicy` that :class:`~.service.GenericDevice`
  consults before a process enters its queue (``CreateProcess``) and before it
  accepts a wiring request (``Subscribe``/``Unsubscribe``).  A refusal is journaled
  with its reason (the process is acknowledged ``Failed: access denied: …``).
  Who the sender is comes from the request's signature (``identity = "signed"``,
  :mod:`~.signing`, any network path), from the TLS link it came over
  (``identity = "tls"``, direct peers only) or from its claim (``"none"``).

The policy file (TOML, ``PLUGCELL_ACL`` or ``GenericDevice(access=...)``)::

    default = "deny"          # what happens when no rule matches ("allow" | "deny")
    identity = "signed"       # "signed": every request must be signed by the Tag's
                              # sender (certificate of the cell's CA, CN = sender),
                              # whatever the path; "tls": the Tag's sender must be the
                              # certificate CN of the link the request's instance came
                              # over (direct peers only); "none"
    signature_window = 30     # seconds: accepted clock difference of a signed request

    [[rule]]                  # first matching rule wins
    effect = "allow"          # "allow" | "deny"
    actions = ["create"]      # "create" (CreateProcess) and/or "wire" (Subscribe)
    senders = ["ROBOT*"]      # shell patterns on the Tag's sender
    services = ["TRACKER"]    # shell patterns on the service's name
    commands = ["*"]          # shell patterns on the command (create only)
    roles = ["service"]       # optional: the sender must be a live service / client
"""

from __future__ import annotations

import fnmatch
import os
import tomllib
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover
    from plugcell.framework.codec import Envelope
    from plugcell.framework.messages import Process
    from plugcell.framework.signing import RequestVerifier

ACTIONS = ("create", "wire")
IDENTITIES = ("none", "tls", "signed")
ENV_ACL = "PLUGCELL_ACL"


def _nobody(_: str) -> Any:
    return None


@dataclass(frozen=True)
class Recipient:
    """What the access policy knows of the service it guards — a value, not the service.

    Parameters
    ----------
    name, cell, instance : str
        The service's name, its cell and its incarnation (a signature is bound to them).
    identities : callable
        ``identities(zid)``: the certificate names of the links to Zenoh session ``zid``
        (``identity = "tls"``); default none.
    role_of : callable
        ``role_of(sender)``: ``"service"``, ``"client"`` or None (not live), for rules
        with ``roles``; default None.
    verifier : callable or None
        Returns the checker of signed requests (``identity = "signed"``); it may raise
        ValueError (no CA configured).
    """

    name: str
    cell: str
    instance: str = ""
    identities: Callable[[str], set[str] | None] = _nobody
    role_of: Callable[[str], str | None] = _nobody
    verifier: Callable[[], RequestVerifier] | None = None


class PolicyError(ValueError):
    """The policy file is malformed (the message says where)."""


# -- Zenoh configuration entries --------------------------------------------------------


def tls_settings(ca: str, cert: str = "", key: str = "", mtls: bool = True) -> dict[str, object]:
    """Zenoh ``transport/link/tls`` entries for a participant of a TLS cell.

    ``ca`` is the cell CA (PEM) every peer's certificate must chain to; ``cert``/``key``
    the participant's own certificate and private key, used both when it listens and
    when it connects; ``mtls`` makes a listener demand a client certificate.  Also
    restricts the links to TLS (``transport/link/protocols``), so no plain TCP peer
    can join.
    """
    tls: dict[str, object] = {"root_ca_certificate": str(ca), "enable_mtls": bool(mtls)}
    if cert or key:
        if not (cert and key):
            raise ValueError("a TLS certificate needs its private key (and vice versa)")
        tls.update(
            listen_certificate=str(cert),
            listen_private_key=str(key),
            connect_certificate=str(cert),
            connect_private_key=str(key),
        )
    return {"transport/link/tls": tls, "transport/link/protocols": ["tls"]}


def usrpwd_settings(user: str = "", password: str = "", dictionary: str = "") -> dict[str, object]:
    """Zenoh ``transport/auth/usrpwd`` entries (user/password authentication).

    ``user``/``password`` are presented when connecting; ``dictionary`` is the file of
    ``user:password`` lines a listener accepts.
    """
    auth: dict[str, object] = {}
    if user or password:
        auth.update(user=user, password=password)
    if dictionary:
        auth["dictionary_file"] = str(dictionary)
    return {"transport/auth/usrpwd": auth} if auth else {}


def zenoh_acl(names: Iterable[str]) -> dict[str, object]:
    """Zenoh ``access_control`` that stops impersonation on the key space (mTLS only).

    ``names`` are the certificate CNs of the cell (its participants).  Every node
    accepts from a peer whose CN is N only the publications, queryables and
    liveliness tokens of N (``plugcell/*/svc/N/**``, ``plugcell/*/live/*/N/*``),
    N's own published requests (``plugcell/*/svc/*/create/N``) and, of a robot service,
    its joint state and live tracked moves (``plugcell/*/joints/N``,
    ``plugcell/*/tracking/N``):
    nobody can publish a forged Shutdown or StateUpdate of another service, answer its
    queries, or declare its presence (which would make the real one withdraw).
    Subscriptions, queries and replies are open to every certified peer; who may
    *create processes* is the service's :class:`AccessPolicy`.  Peers with other CNs
    get nothing (``default_permission`` deny).  Checked on eclipse-zenoh 1.10.2.
    """
    names = list(dict.fromkeys(names))
    if not names:
        raise ValueError("zenoh_acl needs the names of the cell's participants")
    reads = ["declare_subscriber", "query", "reply", "declare_liveliness_subscriber",
             "liveliness_query"]
    writes = ["put", "delete", "declare_queryable", "liveliness_token"]
    rules: list[dict[str, object]] = [
        {"id": "read", "permission": "allow", "flows": ["ingress", "egress"],
         "messages": reads, "key_exprs": ["plugcell/**"]},
        {"id": "send", "permission": "allow", "flows": ["egress"], "messages": writes,
         "key_exprs": ["plugcell/**"]},
    ]
    subjects: list[dict[str, object]] = [{"id": "cell", "cert_common_names": names}]
    policies: list[dict[str, object]] = [
        {"id": "cell", "rules": ["read", "send"], "subjects": ["cell"]}
    ]
    for i, name in enumerate(names):
        rules.append({"id": f"as{i}", "permission": "allow", "flows": ["ingress"],
                      "messages": writes,
                      "key_exprs": [f"plugcell/*/svc/{name}/**", f"plugcell/*/live/*/{name}/*",
                                    f"plugcell/*/svc/*/create/{name}",
                                    f"plugcell/*/joints/{name}",
                                    f"plugcell/*/tracking/{name}"]})
        subjects.append({"id": f"cn{i}", "cert_common_names": [name]})
        policies.append({"id": f"as{i}", "rules": [f"as{i}"], "subjects": [f"cn{i}"]})
    return {"enabled": True, "default_permission": "deny", "rules": rules,
            "subjects": subjects, "policies": policies}


# -- the access policy --------------------------------------------------------------------


def _patterns(value: object, where: str) -> tuple[str, ...]:
    if value is None:
        return ("*",)
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        raise PolicyError(f"{where}: expected a list of non-empty strings, got {value!r}")
    return tuple(value)


def _match(name: str, patterns: Iterable[str]) -> bool:
    return any(fnmatch.fnmatchcase(name, p) for p in patterns)


@dataclass(frozen=True)
class Rule:
    """One rule: ``effect`` for ``actions`` by ``senders`` on ``services``/``commands``."""

    effect: str = "allow"
    actions: tuple[str, ...] = ACTIONS
    senders: tuple[str, ...] = ("*",)
    services: tuple[str, ...] = ("*",)
    commands: tuple[str, ...] = ("*",)
    roles: tuple[str, ...] = ()
    label: str = ""

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], where: str) -> Rule:
        unknown = set(data) - {"effect", "actions", "senders", "services", "commands", "roles"}
        if unknown:
            raise PolicyError(f"{where}: unknown keys {sorted(unknown)}")
        effect = data.get("effect", "allow")
        if effect not in ("allow", "deny"):
            raise PolicyError(f"{where}: effect must be 'allow' or 'deny', got {effect!r}")
        actions = _patterns(data.get("actions", list(ACTIONS)), f"{where}.actions")
        bad = [a for a in actions if a not in ACTIONS]
        if bad:
            raise PolicyError(f"{where}.actions: unknown {bad} (use {list(ACTIONS)})")
        roles = tuple(data.get("roles", ()))
        if any(r not in ("service", "client") for r in roles):
            raise PolicyError(f"{where}.roles: use 'service' and/or 'client', got {list(roles)}")
        return cls(
            effect=effect,
            actions=actions,
            senders=_patterns(data.get("senders"), f"{where}.senders"),
            services=_patterns(data.get("services"), f"{where}.services"),
            commands=_patterns(data.get("commands"), f"{where}.commands"),
            roles=roles,
            label=where,
        )

    def matches(self, action: str, sender: str, service: str, command: str) -> bool:
        return (
            action in self.actions
            and _match(sender, self.senders)
            and _match(service, self.services)
            and (action != "create" or _match(command, self.commands))
        )


@dataclass(frozen=True)
class AccessPolicy:
    """Who may CreateProcess which command on which service, and who may wire it.

    The default instance allows everything (the embedded, easy setting).
    """

    rules: tuple[Rule, ...] = ()
    default: str = "allow"
    identity: str = "none"
    signature_window: float = 30.0
    """With ``identity = "signed"``: the accepted difference, in seconds, between a
    request's timestamp and the service's clock (and how long nonces are kept)."""
    source: str = field(default="", compare=False)

    # construction ------------------------------------------------------------------

    @classmethod
    def allow_all(cls) -> AccessPolicy:
        return cls()

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], source: str = "policy") -> AccessPolicy:
        unknown = set(data) - {"default", "identity", "signature_window", "rule"}
        if unknown:
            raise PolicyError(f"{source}: unknown keys {sorted(unknown)}")
        default = data.get("default", "deny")
        if default not in ("allow", "deny"):
            raise PolicyError(f"{source}: default must be 'allow' or 'deny', got {default!r}")
        identity = data.get("identity", "none")
        if identity not in IDENTITIES:
            raise PolicyError(
                f"{source}: identity must be 'none', 'tls' or 'signed', got {identity!r}"
            )
        window = data.get("signature_window", 30.0)
        if (
            isinstance(window, bool)
            or not isinstance(window, int | float)
            or not 0 < window <= 3600
        ):
            raise PolicyError(
                f"{source}: signature_window must be seconds in (0, 3600], got {window!r}"
            )
        raw = data.get("rule", [])
        if not isinstance(raw, list):
            raise PolicyError(f"{source}: 'rule' must be an array of tables ([[rule]])")
        rules = tuple(
            Rule.from_mapping(r, f"{source}: rule {i + 1}")
            if isinstance(r, Mapping)
            else _raise(f"{source}: rule {i + 1} is not a table")
            for i, r in enumerate(raw)
        )
        return cls(rules=rules, default=default, identity=identity,
                   signature_window=float(window), source=source)

    @classmethod
    def load(cls, path: str | Path) -> AccessPolicy:
        path = Path(path)
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8"))
        except OSError as exc:
            raise PolicyError(f"cannot read access policy {path}: {exc}") from None
        except tomllib.TOMLDecodeError as exc:
            raise PolicyError(f"{path}: {exc}") from None
        return cls.from_mapping(data, str(path))

    @classmethod
    def from_env(cls) -> AccessPolicy:
        """The policy named by ``PLUGCELL_ACL``, or allow-all when unset."""
        path = os.environ.get(ENV_ACL, "").strip()
        return cls.load(path) if path else cls.allow_all()

    # decisions -----------------------------------------------------------------------

    def decide(
        self, action: str, sender: str, service: str, command: str = "", role: str | None = None
    ) -> str:
        """``""`` if allowed, else the reason of the refusal."""
        for rule in self.rules:
            if not rule.matches(action, sender, service, command):
                continue
            if rule.roles and role not in rule.roles:
                continue
            if rule.effect == "allow":
                return ""
            return _denied(action, sender, service, command, f"denied by {rule.label}")
        if self.default == "allow":
            return ""
        return _denied(action, sender, service, command, "no rule allows it")

    def authenticate(
        self,
        service: Recipient,
        envelope: Envelope,
        payload: bytes | bytearray | memoryview | None = None,
    ) -> str:
        """Is the envelope's sender who sent it (``identity``)?  ``""`` if so (or if the
        policy does not ask), else the reason; ``payload``: the request's bytes, which
        ``identity = "signed"`` needs.  A service calls this first and journals a
        refusal as a rejection (nothing is recorded under the claimed sender's name)."""
        return self.check_identity(service, envelope.sender, envelope.instance, envelope, payload)

    def authorize_create(self, service: Recipient, envelope: Envelope,
                         process: Process) -> str:
        """May the (authenticated) sender run this process here?  ``""`` or the reason."""
        sender = process.tag.sender
        return self.decide("create", sender, service.name, process.command.name,
                           service.role_of(sender))

    def authorize_wire(self, service: Recipient, envelope: Envelope, partner: str) -> str:
        """May the (authenticated) sender wire this service to ``partner``?"""
        sender = envelope.sender
        return self.decide("wire", sender, service.name, partner, service.role_of(sender))

    def check_create(
        self,
        service: Recipient,
        envelope: Envelope,
        process: Process,
        payload: bytes | bytearray | memoryview | None = None,
    ) -> str:
        """:meth:`authenticate` then :meth:`authorize_create` in one call."""
        return self.authenticate(service, envelope, payload) or self.authorize_create(
            service, envelope, process
        )

    def check_wire(
        self,
        service: Recipient,
        envelope: Envelope,
        partner: str,
        payload: bytes | bytearray | memoryview | None = None,
    ) -> str:
        """:meth:`authenticate` then :meth:`authorize_wire` in one call."""
        return self.authenticate(service, envelope, payload) or self.authorize_wire(
            service, envelope, partner
        )

    def check_identity(
        self,
        service: Recipient,
        sender: str,
        instance: str,
        envelope: Envelope | None = None,
        payload: bytes | bytearray | memoryview | None = None,
    ) -> str:
        """Is the claimed sender the one who sent the request?

        ``identity = "tls"``: the sender must be the certificate CN of the link to the
        Zenoh session its instance names (peer mode, mTLS).  ``identity = "signed"``:
        the request must carry a valid signature of the sender
        (:meth:`~.signing.RequestVerifier.verify`, the service's verifier).
        """
        if self.identity == "signed":
            if envelope is None:
                return f"access denied: request of {sender} not signed"
            try:
                if service.verifier is None:
                    raise ValueError(f"{service.name} has no checker of signed requests")
                verifier = service.verifier()
            except ValueError as exc:  # no CA configured (SigningError)
                return f"access denied: cannot verify signed requests: {exc}"
            return verifier.verify(
                envelope,
                payload,
                cell=service.cell,
                recipient=service.name,
                recipient_instance=service.instance,
            )
        if self.identity != "tls":
            return ""
        zid = instance[16:] if len(instance) > 16 else ""
        ids = (service.identities(zid) or set()) if zid else set()
        if sender in ids:
            return ""
        seen = ", ".join(sorted(i for i in ids if i)) or "no authenticated link"
        return (
            f"access denied: sender {sender} is not authenticated "
            f"(certificate of its session: {seen})"
        )


def _raise(message: str) -> Rule:
    raise PolicyError(message)


def _denied(action: str, sender: str, service: str, command: str, why: str) -> str:
    what = f"{command} on {service}" if action == "create" else f"wiring {service} to {command}"
    return f"access denied: {sender} may not {'run' if action == 'create' else 'do'} {what} ({why})"


__all__ = [
    "ENV_ACL",
    "IDENTITIES",
    "AccessPolicy",
    "PolicyError",
    "Recipient",
    "Rule",
    "tls_settings",
    "usrpwd_settings",
    "zenoh_acl",
]
