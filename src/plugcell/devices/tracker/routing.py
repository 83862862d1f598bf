"""Who a process is for, and where its output data goes (thesis 7.4, 9.3).

Two things the metrology services need from every process and the framework
does not (yet) hand to ``dispatch``:

* **the requester** — the participant whose state a command reads or changes.  The
  laser tracker keeps BASE and PROBE per robot (eq. 7.2: each robot's own frames)
  and the compute service a workspace per robot.  It is the process's sender, or —
  for a process a service forwards on somebody's behalf — the participant named in
  the option clause ``for=NAME``.
* **routes** — the "redirection of sensory information" of thesis 9.3: "measurement
  data from the laser tracker must be sent to the robot first then forwarded to the
  Matlab software.  A better Command structure will allow for the data to be
  transferred directly to the terminal device".  A process names destinations for
  its output data in option clauses ``to=SERVICE:Command:Option``; the service that
  produces the data creates, for every value, a process ``Command`` at ``SERVICE``
  (service to service, ``create_process``) with that data, on behalf of the
  requester, and the requesting program only orchestrates.

The option grammar (docs/tracker-service.md, "Routing output data")::

    option  = device-option *( ";" clause )
    clause  = "to=" SERVICE ":" COMMAND ":" OPTION    ; up to 4, delivered in order
            / "for=" NAME                             ; only a service may send it

e.g. ``tr2euler; to=COMPUTE:Set Matrix:mT:append``.  ``device-option`` is the
command's own option of Tables 7-2/7-3 and never contains ``;``.

:class:`Routing` implements both for any device: a device holds one, made with its
own handler (``handle(command, device_option, data)``, which reads
``routing.requester``), dispatches through :meth:`Routing.dispatch` and posts its output
data on :attr:`Routing.data_feedback`.  Nothing here is specific to the tracker; it lives
beside it until the framework adopts it (issue 7, section 4).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from plugcell.framework.keys import check_name
from plugcell.framework.messages import Command, CommandTypes, ProcessStates
from plugcell.framework.service import DeviceError

if TYPE_CHECKING:
    from plugcell.framework.service import GenericDevice

log = logging.getLogger(__name__)

SEPARATOR = ";"
MAX_ROUTES = 4
#: Longest wait for one routed delivery (acknowledgement and completion), s.
DELIVERY_TIMEOUT_S = 10.0
#: Longest wait, when a routed stream stops, for the values still on their way, s.
DRAIN_TIMEOUT_S = 10.0
#: Most values waiting for delivery; a stream whose destination cannot keep up ends.
MAX_PENDING = 10_000

__all__ = [
    "MAX_ROUTES",
    "DeliveryError",
    "OptionError",
    "ProcessOption",
    "Route",
    "Routing",
    "fit_to_declaration",
    "format_option",
    "parse_option",
]


class OptionError(ValueError):
    """An option whose clauses cannot be read; the message is the precise reason."""


class DeliveryError(RuntimeError):
    """Routed output data could not be delivered to its destination."""


@dataclass(frozen=True)
class Route:
    """A destination of output data: create ``command`` with ``option`` at ``service``."""

    service: str
    command: str
    option: str = ""

    def __str__(self) -> str:
        return f"{self.service}:{self.command}:{self.option}"


@dataclass(frozen=True)
class ProcessOption:
    """A process option split into the device's own option and the clauses."""

    device: str
    routes: tuple[Route, ...] = ()
    on_behalf_of: str = ""


def parse_route(text: str) -> Route:
    """``SERVICE:Command:Option`` → :class:`Route` (the option may contain ``:``)."""
    parts = text.split(":", 2)
    if len(parts) < 2:
        raise OptionError(f"route {text!r}: expected SERVICE:Command[:Option]")
    service, command = parts[0].strip(), parts[1].strip()
    option = parts[2].strip() if len(parts) == 3 else ""
    try:
        check_name(service, "route service name")
    except ValueError as exc:
        raise OptionError(f"route {text!r}: {exc}") from None
    if not command or len(command) > 64:
        raise OptionError(f"route {text!r}: the command name must have 1 to 64 characters")
    return Route(service, command, option)


def parse_option(text: str) -> ProcessOption:
    """Split ``device-option; to=…; for=…`` (module docstring); OptionError if malformed."""
    device, *clauses = text.split(SEPARATOR)
    routes: list[Route] = []
    on_behalf_of = ""
    for raw in clauses:
        clause = raw.strip()
        if not clause:
            continue
        key, sep, value = clause.partition("=")
        key, value = key.strip(), value.strip()
        if not sep:
            raise OptionError(f"option clause {clause!r}: expected to=SERVICE:Command:Option "
                              "or for=NAME")
        if key == "to":
            routes.append(parse_route(value))
        elif key == "for":
            if on_behalf_of:
                raise OptionError("option: more than one for= clause")
            try:
                on_behalf_of = check_name(value, "for= name")
            except ValueError as exc:
                raise OptionError(f"option clause {clause!r}: {exc}") from None
        else:
            raise OptionError(f"unknown option clause {key!r} (known: to=, for=)")
    if len(routes) > MAX_ROUTES:
        raise OptionError(f"option: {len(routes)} routes, at most {MAX_ROUTES}")
    return ProcessOption(device.strip(), tuple(routes), on_behalf_of)


def format_option(device: str, routes: tuple[Route, ...] = (), on_behalf_of: str = "") -> str:
    """The inverse of :func:`parse_option`."""
    parts = [device, *(f"to={r}" for r in routes)]
    if on_behalf_of:
        parts.append(f"for={on_behalf_of}")
    return "; ".join(parts)


def fit_to_declaration(value: Any, declared: tuple[int, ...]) -> Any:
    """Reshape output data for a destination's input declaration (F.5).

    A vector travels as a one-row matrix to a matrix input and a one-row matrix as a
    vector to a vector input; everything else is left for the destination to judge.
    """
    arr = np.asarray(value)
    if arr.dtype.kind not in "biuf":
        return value
    if len(declared) == 2 and arr.ndim == 1:
        return arr.reshape(1, -1)
    if len(declared) == 1 and arr.ndim == 2 and arr.shape[0] == 1:
        return arr.reshape(-1)
    if len(declared) == 1 and arr.ndim == 0:
        return arr.reshape(1)
    return value


@dataclass(frozen=True)
class RequestContext:
    """What a routed device's handler may know about the process it runs."""

    sender: str
    requester: str
    routes: tuple[Route, ...]


class _Delivery:
    """Delivers the output values of one process to its routes, in order, one at a time."""

    def __init__(self, device: GenericDevice, command: Command, context: RequestContext,
                 on_failure: Callable[[_Delivery, str], None]) -> None:
        self.device = device
        self._on_failure = on_failure
        self.command = command
        self.context = context
        self.queue: asyncio.Queue[Any] = asyncio.Queue(MAX_PENDING)
        self.error: str = ""
        self.delivered = 0
        self.task = asyncio.create_task(self._run(), name=f"{device.name}-route")

    def submit(self, value: Any) -> None:
        if self.error:
            return
        try:
            self.queue.put_nowait(np.array(value, copy=True))
        except asyncio.QueueFull:
            self._fail(f"delivery of {self.command.name} data: {MAX_PENDING} values waiting; "
                       "the destination cannot keep up")

    def _fail(self, reason: str) -> None:
        if not self.error:
            self.error = reason
            self._on_failure(self, reason)

    async def _run(self) -> None:
        while not self.error:
            value = await self.queue.get()
            try:
                for route in self.context.routes:
                    await self._deliver(route, value)
                self.delivered += 1
            except DeliveryError as exc:
                self._fail(str(exc))
            except Exception as exc:  # never a silent loss
                log.exception("%s: routing %s", self.device.name, self.command.name)
                self._fail(f"delivery of {self.command.name} data failed: {exc!r}")
            finally:
                self.queue.task_done()

    async def check(self) -> None:
        """Before any data: every destination must be a service with that command."""
        for route in self.context.routes:
            await self._target(route)

    async def _target(self, route: Route) -> Command:
        device = self.device
        what = f"delivery of {self.command.name} data to {route.service}:{route.command}"
        try:
            if route.service not in device.participant.partners:
                await device.participant.subscribe(route.service, DELIVERY_TIMEOUT_S)
            catalogue = device.participant.partners[route.service].device
        except Exception as exc:  # PartnerError, timeouts: the reason is in the message
            raise DeliveryError(f"{what} failed: {exc}") from None
        target = catalogue.command(route.command)
        if target is None:
            known = ", ".join(c.name for c in catalogue.commands) or "none"
            raise DeliveryError(f"{what} failed: unknown command {route.command!r} for "
                                f"{route.service} (commands: {known})")
        return target

    async def _deliver(self, route: Route, value: Any) -> None:
        what = f"delivery of {self.command.name} data to {route.service}:{route.command}"
        device = self.device
        value = fit_to_declaration(value, (await self._target(route)).input_data_size)
        option = format_option(route.option, on_behalf_of=self.context.requester)
        call = await device.participant.create_process(
            route.service, route.command, option, value, timeout=DELIVERY_TIMEOUT_S
        )
        final = await call.result()
        if final.state is not ProcessStates.Completed:
            raise DeliveryError(f"{what} failed: {final.reason}")

    async def drain(self, timeout: float) -> None:
        """Wait until every submitted value is delivered (DeliveryError if one failed)."""
        waiter = asyncio.create_task(self.queue.join())
        done, _ = await asyncio.wait({waiter, self.task}, timeout=timeout,
                                     return_when=asyncio.FIRST_COMPLETED)
        waiter.cancel()
        if self.error:
            raise DeliveryError(self.error)
        if not done:
            raise DeliveryError(
                f"delivery of {self.command.name} data: {self.queue.qsize()} values still "
                f"undelivered after {timeout:g} s"
            )

    async def close(self) -> None:
        self.task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self.task


class _RoutingPort:
    """Wraps the DataFeedback port: each value also goes to ``route`` (from any thread)."""

    def __init__(self, inner: Any, route: Callable[[Any], object]) -> None:
        self._inner = inner
        self._route = route
        self.name = inner.name

    def post(self, value: Any) -> None:
        self._route(value)
        self._inner.post(value)


#: A routed device's handler: ``handle(command, device_option, data)`` → feedback code.
Handler = Callable[[Command, str, Any], Awaitable[str | None]]


class Routing:
    """The requester and the routes of a device's processes (module doc), for the device
    that holds it: ``Routing(handle)``, bound to the hosting service with the device."""

    def __init__(self, handle: Handler) -> None:
        self.handle = handle
        self.service: GenericDevice | None = None
        self.data_feedback: Any = None
        """The DataFeedback port the device posts its output on: each value also goes
        to the process's routes."""
        self._context: RequestContext | None = None
        self._delivery: _Delivery | None = None
        self._stream_delivery: _Delivery | None = None

    def bind(self, service: GenericDevice) -> None:
        """Route the output the device posts to ``service``'s DataFeedback port."""
        self.service = service
        self.data_feedback = _RoutingPort(
            service.data_feedback, lambda value: service.call_in_loop(self._submit, value))

    @property
    def requester(self) -> str:
        """The participant the running process is for ("" while the service itself stops a
        stream whose sender is gone)."""
        return self._context.requester if self._context is not None else ""

    @property
    def context(self) -> RequestContext | None:
        return self._context

    # -- the framework side ---------------------------------------------------------------

    async def dispatch(self, command: Command, option: str, data: Any) -> str | None:
        """Split the option, establish the requester, run the handler, deliver."""
        service = self.service
        assert service is not None, "Routing.dispatch before bind"
        if not service.sender:  # the framework stops the stream of a lost sender itself
            return await self._stop_routed(command, data, lost=True)
        try:
            parsed = parse_option(option)
        except OptionError as exc:
            raise DeviceError(str(exc)) from None
        requester = service.sender
        if parsed.on_behalf_of:
            if not service.participant.is_alive(service.sender, "service"):
                raise DeviceError(
                    f"for={parsed.on_behalf_of}: only a service may act on behalf of another "
                    f"participant ({service.sender} is not a live service)"
                )
            requester = parsed.on_behalf_of
        if parsed.routes and not command.gives_output:
            raise DeviceError("no output data to route (to=)")
        self._context = RequestContext(service.sender, requester, parsed.routes)
        try:
            if command.type is CommandTypes.StopData:
                return await self._stop_routed(command, data, lost=False, option=parsed.device)
            delivery = (_Delivery(service, command, self._context, self._delivery_failed)
                        if parsed.routes else None)
            if delivery is not None:
                try:
                    await delivery.check()
                except DeliveryError as exc:
                    await delivery.close()
                    raise DeviceError(str(exc)) from None
            self._delivery = delivery
            try:
                code = await self.handle(command, parsed.device, data)
            except BaseException:
                if delivery is not None:
                    await delivery.close()
                raise
            finally:
                self._delivery = None
            if delivery is None:
                return code
            if command.type is CommandTypes.MultipleData:
                self._stream_delivery = delivery
                return code
            try:
                await delivery.drain(DRAIN_TIMEOUT_S)
            except DeliveryError as exc:
                raise DeviceError(f"measured, but {exc}") from None
            finally:
                await delivery.close()
            return code
        finally:
            self._context = None

    async def _stop_routed(self, command: Command, data: Any, *, lost: bool,
                           option: str = "") -> str | None:
        delivery, self._stream_delivery = self._stream_delivery, None
        code = await self.handle(command, option, data)
        if delivery is None:
            return code
        try:
            if not lost and not delivery.error:
                await delivery.drain(DRAIN_TIMEOUT_S)
        except DeliveryError as exc:
            raise DeviceError(str(exc)) from None
        finally:
            await delivery.close()
        return code

    def _submit(self, value: Any) -> None:
        delivery = self._delivery or self._stream_delivery
        if delivery is not None:
            delivery.submit(value)

    def _delivery_failed(self, delivery: _Delivery, reason: str) -> None:
        """A routed stream could not deliver: end it (the reason reaches the requester)."""
        if delivery is self._stream_delivery and self.service is not None:
            log.warning("%s: %s", self.service.name, reason)
            self.service.cmd_feedback.post(reason)
