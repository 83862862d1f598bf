"""Helpers of the security tests: the policy, free ports, a TLS cell."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "framework"))

from framework_testlib import Proc

from plugcell.framework.transport import TransportConfig

POLICY = """
default = "deny"
identity = "tls"

[[rule]]                       # the robot wired to the tracker may command it
actions = ["create"]
senders = ["ROBOT1"]
services = ["TRACKER"]
commands = ["Set Base", "Set Probe", "Move", "Single Measurement"]

[[rule]]                       # only the cell controller may wire
actions = ["wire"]
senders = ["CONTROLLER"]

[[rule]]                       # and run things on the robots
actions = ["create"]
senders = ["CONTROLLER"]
services = ["R1"]
"""


NAMES = ("TRACKER", "R1", "ROBOT1", "ROBOT2", "CONTROLLER")


def issue_cell_certificates(
    base: Path, ca_name: str, names: tuple[str, ...] = NAMES
) -> tuple[Path, Path, Path]:
    """``base/certs`` (the cell's CA and a certificate for each of ``names``),
    ``base/rogue`` (another CA with a ROBOT1 of its own) and ``base/home``."""
    from plugcell.framework.certificates import create_ca, issue_certificate

    certs, rogue, home = base / "certs", base / "rogue", base / "home"
    create_ca(certs, ca_name)
    for name in names:
        issue_certificate(certs, name)
    create_ca(rogue, "rogue")
    issue_certificate(rogue, "ROBOT1")
    return certs, rogue, home


@dataclass
class SecureCell:
    """A TLS cell: its CA folder, a rogue CA, the tracker's endpoint and journal home."""

    name: str
    certs: Path
    rogue: Path
    home: Path
    endpoint: str
    tracker: Proc
    robot: Proc | None = None

    def transport(self, who: str | None, folder: Path | None = None) -> TransportConfig:
        """A client's transport: TLS to the tracker with ``who``'s certificate (None: none)."""
        folder = folder or self.certs
        return TransportConfig(
            listen=(),
            connect=(self.endpoint,),
            multicast=False,
            tls_ca=str(folder / "ca.pem"),
            tls_cert=str(folder / f"{who}.pem") if who else "",
            tls_key=str(folder / f"{who}.key") if who else "",
            cell_names=NAMES,
        )
