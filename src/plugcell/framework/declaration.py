"""What a device declares: its kind, its names and its command catalogue — a value.

Thesis 5.2.3.3: ``StateInitialize`` fills ``DeviceInfo`` with the device's vendor, info
and command catalogue.  Here that is a :class:`Declaration`, a frozen value a device
interface carries (``declaration``), checked once when it is made; the service that
hosts the device (:class:`~plugcell.framework.service.GenericDevice`) builds its
DeviceInfo from it.
"""

from __future__ import annotations

from dataclasses import dataclass

from plugcell.framework.messages import (
    Command,
    CommandTypes,
    ConnectionStates,
    Device,
    DeviceStates,
)


@dataclass(frozen=True)
class Declaration:
    """A device's identity and catalogue.

    Parameters
    ----------
    kind : str
        Registry name of the device kind (``plugcell serve KIND``); may be empty for a
        device that is not served by kind.
    commands : tuple of Command
        The command catalogue (``state.DeviceInfo.Commands``, 5.2.3.3), checked by
        :func:`check_catalogue`.
    default_name : str
        The service's name when none is given (``""``: ``kind`` in capitals).
    vendor, info : str
        DeviceInfo's vendor and free text.
    express_updates : bool
        Publish process notifications with Zenoh's ``express`` flag (sent at once, not
        held for Zenoh's own batching): the service already sends one sample per sender
        per loop turn (:class:`~plugcell.framework.outbox.Outbox`), so holding it only
        adds latency.
    """

    kind: str
    commands: tuple[Command, ...] = ()
    default_name: str = ""
    vendor: str = ""
    info: str = ""
    express_updates: bool = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "commands", tuple(self.commands))
        check_catalogue(self.kind or "device", self.commands)

    def name(self, given: str | None = None) -> str:
        """The service's name: ``given``, else the default name, else ``KIND``."""
        return given or self.default_name or (self.kind or "device").upper()

    def device_info(self, name: str) -> Device:
        """The DeviceInfo (Table 5-1) of a service named ``name`` that hosts such a
        device, as it starts: Ready, Offline."""
        return Device(name=name, vendor=self.vendor, info=self.info, commands=self.commands,
                      kind=self.kind, connection=ConnectionStates.Offline,
                      state=DeviceStates.Ready)


def check_catalogue(owner: str, commands: tuple[Command, ...]) -> None:
    """Check a command catalogue: unique names, a StopData for any MultipleData, a type
    wherever a size is declared (TypeError naming ``owner`` and the command)."""
    names = [c.name for c in commands]
    if len(set(names)) != len(names):
        raise TypeError(f"{owner}: duplicate command names in {names}")
    types = {c.type for c in commands}
    if CommandTypes.MultipleData in types and CommandTypes.StopData not in types:
        raise TypeError(f"{owner}: a MultipleData command needs a StopData command to stop it")
    for c in commands:
        if (
            c.type in (CommandTypes.SingleData, CommandTypes.MultipleData)
            and c.output_data_type is None
            and c.output_data_size != (0,)
        ):
            raise TypeError(f"{owner}: {c.name} declares an output size without a type")
        if c.input_data_size != (0,) and c.input_data_type is None:
            raise TypeError(f"{owner}: {c.name} declares an input size without a type")


__all__ = ["Declaration", "check_catalogue"]
