"""Two Linux network namespaces joined by a veth pair: a two-machine cell on one host.

Used by the deployment test (issue section 8) and ``plugcell bench transport
--networked`` (thesis Table 5-6: 100 Mbit/s Ethernet, shaped here with ``tc``).
Needs root and ``ip``; everything it creates is removed by :meth:`VethPair.close`,
and traffic stays on the addresses it creates.
"""

from __future__ import annotations

import os
import random
import shutil
import subprocess
from dataclasses import dataclass


def netns_available() -> str:
    """Empty string if namespaces can be created here, else why not."""
    if os.geteuid() != 0:
        return "needs root"
    if shutil.which("ip") is None:
        return "needs the ip command (iproute2)"
    probe = f"pcprobe{os.getpid()}"
    try:
        _ip("netns", "add", probe)
    except subprocess.CalledProcessError as exc:
        return f"cannot create a network namespace: {exc.stderr.strip()}"
    _ip("netns", "del", probe, check=False)
    return ""


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["ip", *args], capture_output=True, text=True, check=check, timeout=30)


@dataclass
class VethPair:
    """Namespaces ``a`` and ``b`` with addresses ``addr_a``/``addr_b`` on one /24."""

    a: str
    b: str
    addr_a: str
    addr_b: str

    @classmethod
    def create(cls, rate_mbit: float | None = None) -> VethPair:
        """Create both namespaces and the link; shape it to ``rate_mbit`` if given."""
        tag = f"{os.getpid() % 100000}{random.randrange(100):02d}"
        subnet = f"10.{random.randrange(200, 250)}.{random.randrange(1, 250)}"
        pair = cls(f"pca{tag}", f"pcb{tag}", f"{subnet}.1", f"{subnet}.2")
        va, vb = f"pva{tag}", f"pvb{tag}"
        try:
            _ip("netns", "add", pair.a)
            _ip("netns", "add", pair.b)
            _ip("link", "add", va, "type", "veth", "peer", "name", vb)
            _ip("link", "set", va, "netns", pair.a)
            _ip("link", "set", vb, "netns", pair.b)
            for ns, dev, addr in ((pair.a, va, pair.addr_a), (pair.b, vb, pair.addr_b)):
                _ip("-n", ns, "addr", "add", f"{addr}/24", "dev", dev)
                _ip("-n", ns, "link", "set", dev, "up")
                _ip("-n", ns, "link", "set", "lo", "up")
                if rate_mbit:  # token bucket: the 100 Mbit/s Ethernet of thesis 5.3
                    tbf = [
                        "tc",
                        "qdisc",
                        "add",
                        "dev",
                        dev,
                        "root",
                        "tbf",
                        "rate",
                        f"{rate_mbit}mbit",
                        "burst",
                        "64kb",
                        "latency",
                        "100ms",
                    ]
                    subprocess.run(
                        ["ip", "netns", "exec", ns, *tbf],
                        check=True,
                        capture_output=True,
                        text=True,
                        timeout=30,
                    )
        except (subprocess.CalledProcessError, OSError):
            pair.close()
            raise
        return pair

    def argv(self, ns: str, argv: list[str]) -> list[str]:
        """``argv`` run inside namespace ``ns``."""
        return ["ip", "netns", "exec", ns, *argv]

    def close(self) -> None:
        """Delete both namespaces (and with them the veth pair)."""
        for ns in (self.a, self.b):
            _ip("netns", "del", ns, check=False)

    def __enter__(self) -> VethPair:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
