"""The transport adapter: one Zenoh session, the cell's key layouts, and the hand-off.

A participant (``participant.py``) and a service (``service.py``) speak of *names* and
*doors* — "serve Get for CAMERA", "follow the updates sent to ROBOT", "a request door
from ROBOT to TRACKER" — and a :class:`Bus` turns them into Zenoh declarations on the
keys of :class:`~plugcell.framework.keys.KeySpace`.  It is the only part of plugcell that
holds a ``zenoh.Session`` and the only one that builds or parses keys (with ``keys.py``,
whose layouts it applies); everything above it is transport-free.

Zenoh calls its callbacks on its own threads and forbids blocking in them; a bus given a
``hand_off`` (a participant's :class:`~plugcell.framework.port.Port`) passes each
``(handler, item)`` to it, so every handler runs on the participant's event loop in
arrival order.  A bus without one (the simulated world, ``sim/controller/reflector.py``)
calls handlers on Zenoh's threads: they must be thread-safe and quick.  Either way the
callback first keeps the Python thread state of Zenoh's thread alive
(:func:`~plugcell.framework.threadstate.pin`), so that a sample does not create and
destroy one.

Doors (docs/protocol.md, "Key space"): ``get``, ``subscribe`` and ``create`` are a
service's queryables; a service also takes CreateProcess published on its request key
(one per sender), answers on each sender's process key and publishes its ``state``,
``connection`` and ``shutdown`` notifications.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Literal

import zenoh
from zenoh.handlers import Callback

from plugcell.framework.keys import KeySpace, Presence, Role
from plugcell.framework.threadstate import pin
from plugcell.framework.transport import TransportConfig, open_session

Handler = Callable[[Any], None]
HandOff = Callable[[tuple[Handler, Any]], None]
QueryDoor = Literal["get", "subscribe", "create"]
Notification = Literal["state", "connection", "shutdown"]

#: What a bus declares, to undeclare when done: a subscriber, queryable, publisher, token.
Entity = Any

#: What a bus's operations raise when the transport refuses (e.g. the session closed).
TransportError = zenoh.ZError


class Bus:
    """A participant's transport: its Zenoh session on one cell's keys (module doc).

    Parameters
    ----------
    session
        An open Zenoh session; the bus closes it in :meth:`close`.
    keys
        The key layouts of the cell.
    hand_off
        Where Zenoh's callbacks put ``(handler, item)`` for the handler to run on the
        owner's event loop; ``None``: handlers run on Zenoh's threads.
    owns_session
        Whether :meth:`close` closes the session (False for a :meth:`direct` view).
    """

    def __init__(self, session: zenoh.Session, keys: KeySpace,
                 hand_off: HandOff | None = None, *, owns_session: bool = True) -> None:
        self.session = session
        """The Zenoh session (for the framework's tests and the raw-Zenoh benchmark)."""
        self.keys = keys
        self._hand_off = hand_off
        self._owns_session = owns_session

    @classmethod
    def connect(cls, transport: TransportConfig | None, keys: KeySpace,
                hand_off: HandOff | None = None) -> Bus:
        """Open a session with ``transport`` (blocking: call it in a thread from a loop)."""
        return cls(open_session(transport), keys, hand_off)

    # -- the session ---------------------------------------------------------------------

    @property
    def zid(self) -> str:
        """The session's Zenoh id (the end of every incarnation id)."""
        return str(self.session.zid())

    @property
    def is_open(self) -> bool:
        return not self.session.is_closed()

    def close(self) -> None:
        """Close the session (blocking; what was declared on it goes with it) — unless
        this bus is a :meth:`direct` view of another's, which closes nothing."""
        if self._owns_session:
            self.session.close()

    def direct(self) -> Bus:
        """A view of this bus — same session, same keys — whose handlers run on Zenoh's
        threads (no hand-off): for quick, thread-safe handlers that must not wait for
        the owner's event loop, such as a reflector of the simulated world published
        from a client (apps/demo/services.py).  Its :meth:`close` closes nothing."""
        return Bus(self.session, self.keys, owns_session=False)

    def link_identities(self, zid: str) -> set[str]:
        """The authenticated identities (TLS certificate names) of this session's links
        to the peer whose Zenoh id is ``zid``."""
        return {
            str(link.auth_identifier or "")
            for link in self.session.info.links()
            if str(link.zid) == zid
        }

    def _callback(self, handler: Handler) -> Callback:
        return Callback(self._on_zenoh_thread(handler), indirect=False)

    def _query_callback(self, on_reply: Handler, on_done: Handler) -> Callback:
        done = self._on_zenoh_thread(on_done)
        return Callback(self._on_zenoh_thread(on_reply), lambda: done(None), indirect=False)

    def _on_zenoh_thread(self, handler: Handler) -> Handler:
        """What Zenoh calls for each item: pin its thread's Python state, then hand the
        item off to the owner's loop (or, without a hand-off, run ``handler`` here)."""
        hand_off = self._hand_off
        if hand_off is None:
            def run(item: Any) -> None:
                pin()
                handler(item)
            return run

        def post(item: Any) -> None:
            pin()
            hand_off((handler, item))
        return post

    # -- presence (liveliness) -------------------------------------------------------------

    def announce(self, role: Role, name: str, instance: str) -> Entity:
        """Declare this participant's liveliness token (undeclare it to leave)."""
        return self.session.liveliness().declare_token(self.keys.live(role, name, instance))

    def watch_presence(self, handler: Callable[[Presence, bool], None]) -> Entity:
        """``handler(presence, joined)`` for every token of the cell, present ones first."""
        keys = self.keys

        def on_sample(sample: zenoh.Sample) -> None:
            presence = keys.parse_live(str(sample.key_expr))
            if presence is not None:
                handler(presence, sample.kind == zenoh.SampleKind.PUT)

        return self.session.liveliness().declare_subscriber(
            keys.live_all(), self._callback(on_sample), history=True)

    def find_service(self, name: str, on_found: Callable[[Presence], None],
                     on_done: Handler, timeout: float = 1.0) -> None:
        """Ask which instances of service ``name`` are alive: ``on_found`` for each,
        then ``on_done(None)``."""
        keys = self.keys

        def on_reply(reply: Any) -> None:
            if reply.ok is not None:
                presence = keys.parse_live(str(reply.ok.key_expr))
                if presence is not None:
                    on_found(presence)

        self.session.liveliness().get(keys.live_services(name),
                                      self._query_callback(on_reply, on_done), timeout=timeout)

    # -- a service's doors -----------------------------------------------------------------

    def serve(self, door: QueryDoor, name: str, handler: Callable[[zenoh.Query], None]) -> Entity:
        """Answer the queries on service ``name``'s ``door`` with ``handler(query)``."""
        key = {"get": self.keys.get, "subscribe": self.keys.subscribe,
               "create": self.keys.create}[door](name)
        return self.session.declare_queryable(key, self._callback(handler))

    def take_requests(self, name: str,
                      handler: Callable[[str, zenoh.Sample], None]) -> Entity:
        """``handler(sender, sample)`` for every CreateProcess published to service
        ``name`` (``sender``: the last segment of the key, still to be checked)."""
        keys = self.keys

        def on_sample(sample: zenoh.Sample) -> None:
            handler(keys.request_sender(str(sample.key_expr)), sample)

        return self.session.declare_subscriber(keys.requests(name), self._callback(on_sample))

    def process_publisher(self, name: str, sender: str, *, express: bool) -> Entity:
        """Service ``name``'s publisher of acknowledgements and updates to ``sender``."""
        return self.session.declare_publisher(
            self.keys.process(name, sender),
            congestion_control=zenoh.CongestionControl.BLOCK, express=express)

    def notify(self, kind: Notification, name: str, payload: bytes) -> None:
        """Publish service ``name``'s ``state``, ``connection`` or ``shutdown``
        notification (its subscribed partners hear it)."""
        key = {"state": self.keys.state, "connection": self.keys.connection,
               "shutdown": self.keys.shutdown}[kind](name)
        self.session.put(key, payload)

    # -- what a participant follows and asks ---------------------------------------------

    def follow_processes(self, name: str, handler: Callable[[zenoh.Sample], None]) -> Entity:
        """``handler(sample)`` for every acknowledgement/update sent to participant ``name``."""
        return self.session.declare_subscriber(self.keys.process_for(name),
                                               self._callback(handler))

    def watch_processes(self, handler: Callable[[str, zenoh.Sample], None]) -> Entity:
        """``handler(service, sample)`` for every process update of the cell."""
        keys = self.keys

        def on_sample(sample: zenoh.Sample) -> None:
            where = keys.parse_process(str(sample.key_expr))
            if where is not None:
                handler(where[0], sample)

        return self.session.declare_subscriber(keys.all_processes(), self._callback(on_sample))

    def follow_notifications(self, partner: str,
                             handler: Callable[[zenoh.Sample], None]) -> Entity:
        """``handler(sample)`` for every notification of service ``partner``."""
        return self.session.declare_subscriber(self.keys.notifications(partner),
                                               self._callback(handler))

    def query(self, door: QueryDoor, name: str, payload: bytes | None,
              on_reply: Handler, on_done: Handler, *, timeout: float,
              everyone: bool = False) -> None:
        """Query service ``name``'s ``door`` (``name`` ``"*"``: every service, with
        ``everyone``): ``on_reply(reply)`` for each reply, then ``on_done(None)``."""
        key = {"get": self.keys.get, "subscribe": self.keys.subscribe,
               "create": self.keys.create}[door](name)
        self.session.get(
            key,
            self._query_callback(on_reply, on_done),
            payload=payload,
            timeout=timeout,
            target=zenoh.QueryTarget.ALL if everyone else zenoh.QueryTarget.BEST_MATCHING,
            consolidation=zenoh.QueryConsolidation(zenoh.ConsolidationMode.NONE),
        )

    def request_door(self, partner: str, sender: str) -> Entity:
        """``sender``'s publisher of CreateProcess to service ``partner`` (its
        ``matching_status`` says whether ``partner`` takes published requests)."""
        return self.session.declare_publisher(
            self.keys.request(partner, sender),
            express=True,
            congestion_control=zenoh.CongestionControl.BLOCK,
        )

    # -- a robot's joint state (devices/robot/joint_state.py) ----------------------------

    def joint_state_publisher(self, name: str) -> Entity:
        """Robot service ``name``'s publisher of its joint state (drops rather than blocks:
        a display stream, the next state replaces a lost one)."""
        return self.session.declare_publisher(
            self.keys.joints(name), congestion_control=zenoh.CongestionControl.DROP)

    def watch_joint_states(self, handler: Callable[[str, bytes], None]) -> Entity:
        """``handler(robot service, payload)`` for every joint state of the cell."""
        return self._watch_named(self.keys.joints(), self.keys.parse_joints, handler)

    def _watch_named(self, pattern: str, parse: Callable[[str], str | None],
                     handler: Callable[[str, bytes], None]) -> Entity:
        """``handler(name, payload)`` for every sample on ``pattern`` whose key ``parse``
        names a service (a display stream of each robot service)."""

        def on_sample(sample: zenoh.Sample) -> None:
            name = parse(str(sample.key_expr))
            if name is not None:
                handler(name, sample.payload.to_bytes())

        return self.session.declare_subscriber(pattern, self._callback(on_sample))

    # -- a robot's tracked move as it goes (devices/robot/live_tracking.py) -------------

    def tracking_publisher(self, name: str) -> Entity:
        """Robot service ``name``'s publisher of its live tracked moves (drops rather than
        blocks: a display stream, never a late robot cycle)."""
        return self.session.declare_publisher(
            self.keys.tracking(name), congestion_control=zenoh.CongestionControl.DROP)

    def watch_tracking(self, handler: Callable[[str, bytes], None]) -> Entity:
        """``handler(robot service, payload)`` for every live tracking batch of the cell."""
        return self._watch_named(self.keys.tracking(), self.keys.parse_tracking, handler)

    # -- the simulated world's reflectors (sim/world.py) ---------------------------

    def reflector(self, name: str, latest: Callable[[], bytes | None]) -> tuple[Entity, Entity]:
        """A publisher of reflector ``name``'s true pose, and a queryable answering each
        query with ``latest()`` (nothing while it is None)."""
        key = self.keys.reflector(name)

        def on_query(query: zenoh.Query) -> None:
            last = latest()
            if last is not None:
                query.reply(key, last)

        return self.session.declare_publisher(key), self.session.declare_queryable(
            key, self._callback(on_query))

    def watch_reflectors(self, handler: Callable[[bytes], None]) -> Entity:
        """``handler(payload)`` for every pose a reflector of the cell publishes."""
        return self.session.declare_subscriber(
            self.keys.reflector(), self._callback(lambda s: handler(s.payload.to_bytes())))

    def query_reflectors(self, timeout: float) -> list[bytes]:
        """The latest pose of every reflector of the cell (blocking, up to ``timeout`` s)."""
        out = []
        for reply in self.session.get(self.keys.reflector(), timeout=timeout):
            if reply.ok is not None:
                out.append(reply.ok.payload.to_bytes())
        return out


__all__ = ["Bus", "Entity", "TransportError"]
