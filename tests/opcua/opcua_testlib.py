"""Helpers of the OPC UA tests: the node-opcua harness (tests/opcua/js) and free ports."""

from __future__ import annotations

import json
import shutil
import subprocess
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from childproc import Proc, plugcell_argv, until

from plugcell.sim.ports import free_port

JS = Path(__file__).resolve().parent / "js"


def unique_cell(prefix: str = "ua") -> str:
    return f"{prefix}-{uuid.uuid4().hex[:10]}"


@dataclass
class UaCell:
    """A cell of services run as processes, and ``plugcell opcua serve`` for it."""

    name: str
    home: Path
    env: dict[str, str]
    procs: list[Proc] = field(default_factory=list)
    url: str = ""

    def start(self, *args: str, env: dict[str, str] | None = None) -> Proc:
        proc = Proc(plugcell_argv(*args), {**self.env, **(env or {})})
        self.procs.append(proc)
        return proc

    def serve(self, kind: str, *extra: str, env: dict[str, str] | None = None) -> Proc:
        proc = self.start("serve", kind, "--cell", self.name, *extra, env=env)
        proc.wait_line(lambda line: "serving in cell" in line, 30.0)
        return proc

    def gateway(self, *extra: str, env: dict[str, str] | None = None) -> tuple[Proc, str]:
        port = free_port()
        proc = self.start("opcua", "serve", "--cell", self.name, "--port", str(port), *extra,
                          env=env)
        line = proc.wait_line(lambda line: "OPC UA gateway" in line, 30.0)
        return proc, line.split(" at ")[1].split()[0]

    def stop(self) -> None:
        for proc in reversed(self.procs):
            proc.stop()


def ensure_node_harness() -> None:
    """node and the harness's node_modules (``npm ci`` once if missing; `make test` does it)."""
    assert shutil.which("node"), "node is not installed (.ci/run installs nodejs)"
    if not (JS / "node_modules" / "node-opcua").is_dir():
        assert shutil.which("npm"), "npm is not installed (.ci/run installs npm)"
        subprocess.run(["npm", "ci", "--no-audit", "--no-fund", "--silent"], cwd=JS,
                       check=True, timeout=300)


def run_js(script: str, *args: str, options: dict[str, Any] | None = None,
           limit_s: float = 30.0) -> Any:
    """Run ``node js/SCRIPT args… OPTIONS`` (bounded) and return the JSON it printed."""
    opts = {"limitMs": int(limit_s * 1000), **(options or {})}
    proc = subprocess.run(
        ["node", str(JS / script), *args, json.dumps(opts)],
        capture_output=True, text=True, timeout=limit_s + 10, cwd=JS,
    )
    assert proc.returncode == 0, f"{script} {args[:1]} failed ({proc.returncode}):\n{proc.stderr}"
    lines = [line for line in proc.stdout.splitlines() if line.startswith(("{", "["))]
    assert lines, f"{script} printed no result:\n{proc.stdout}\n{proc.stderr}"
    return json.loads(lines[-1])


def shown_services(url: str, cell: str, timeout: float = 5.0, **login: Any) -> set[str]:
    """The services under ``Objects/Cell`` now, read with asyncua (a quick poll for the
    tests' waits; what they check is read by node-opcua)."""
    import asyncio

    from asyncua import Client, ua

    async def read() -> set[str]:
        client = Client(url, timeout=timeout)
        if login.get("user"):
            client.set_user(login["user"])
            client.set_password(login["password"])
        async with client:
            idx = await client.get_namespace_index(f"urn:plugcell:cell:{cell}")
            children = await client.get_node(ua.NodeId("Cell", idx)).get_children()
            return {(await c.read_browse_name()).Name for c in children}

    return asyncio.run(read())


def wait_shown(url: str, cell: str, want: set[str], gone: set[str] = frozenset(),
               timeout: float = 30.0) -> set[str]:
    """Wait until the gateway shows every service of ``want`` and none of ``gone``."""
    seen: set[str] = set()

    def ready() -> bool:
        seen.clear()
        seen.update(shown_services(url, cell))
        return want <= seen and not (gone & seen)

    until(ready, timeout, f"services {sorted(want)} shown, {sorted(gone)} not")
    return seen
