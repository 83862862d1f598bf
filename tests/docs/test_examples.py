"""The docs are tests (issue 39): every ``sh``/``console`` example of README.md and
docs/*.md runs as a new user pastes it, in a scratch folder of its own, with the
``plugcell`` command of this checkout; what a page shows a command printing is what it
prints (the rules: ``docexamples``).

One test per page: its blocks run in order in one folder (an example may use what an
earlier one on the page made), each command as ``bash`` in a process group of its own;
what an example starts in the background (``&``) is stopped with its group when the page
ends.  Blocks marked ``<!-- docs-test: skip reason="…" -->`` (hardware, a network) are
listed with their reason; the count of examples run and skipped is in pytest's summary
(``tests/docs/conftest.py``).

The ``plugcell`` (and ``python``) a page runs is a shim for this interpreter: the code
under test is the checkout's (``PYTHONPATH`` made absolute), not whatever is installed.
Every page runs in a cell of its own (``PLUGCELL_CELL``) so that tests running beside it
are not in its ``plugcell services``.  ``PLUGCELL_DATA`` is the project's reference data
(``shared/data``) where present; an example that needs it is skipped without it.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest
from docexamples import RESULTS, Block, output_matches, read_blocks, shows_error
from shared_data import DATA

import plugcell

REPO = Path(__file__).resolve().parents[2]
PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
BACKGROUND_WAIT_S = 60.0


def _pages() -> list[Path]:
    return [p for p in PAGES if any(b.kind != "file" for b in read_blocks(p, _name(p)))]


def _name(path: Path) -> str:
    return str(path.relative_to(REPO))


def _environment(tmp: Path, page: str) -> dict[str, str]:
    """The environment of a page's commands: shims first on PATH, this checkout's code."""
    shims = tmp / ".shims"
    shims.mkdir()
    for name, run in (("plugcell", "-m plugcell"), ("python", ""), ("python3", "")):
        shim = shims / name
        shim.write_text(f'#!/bin/sh\nexec "{sys.executable}" {run} "$@"\n')
        shim.chmod(0o755)
    code = str(Path(plugcell.__file__).resolve().parents[1])
    extra = [str(Path(p).resolve()) for p in os.environ.get("PYTHONPATH", "").split(os.pathsep)
             if p]
    env = dict(os.environ)
    env.update(
        PATH=f"{shims}{os.pathsep}{env.get('PATH', '')}",
        PYTHONPATH=os.pathsep.join([code, *extra]),
        PLUGCELL_CELL=f"docs-{Path(page).stem}-{uuid.uuid4().hex[:8]}",
        PLUGCELL_HOME=str(tmp / ".plugcell-home"),
        PYTHONUNBUFFERED="1",
    )
    env.pop("PLUGCELL_DATA", None)
    if DATA.is_dir():
        env["PLUGCELL_DATA"] = str(DATA)
    return env


class _Page:
    """Runs one page's commands in its folder and stops what they leave running."""

    def __init__(self, folder: Path, env: dict[str, str], logs: Path) -> None:
        self.folder, self.env, self.logs = folder, env, logs
        self.groups: list[int] = []
        self.n = 0

    def run(self, script: str, timeout_s: float) -> tuple[int, Path]:
        """Run ``script`` with bash in the page's folder; its status and output file."""
        self.n += 1
        out = self.logs / f"{self.n:03d}.out"
        with out.open("wb") as sink:
            proc = subprocess.Popen(["bash", "-c", script], cwd=self.folder, env=self.env,
                                    stdin=subprocess.DEVNULL, stdout=sink,
                                    stderr=subprocess.STDOUT, start_new_session=True)
        self.groups.append(proc.pid)
        try:
            status = proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(10)
            pytest.fail(f"did not end within {timeout_s:g} s:\n{script}\n--- it printed:\n"
                        f"{_tail(out)}")
        return status, out

    def stop(self) -> None:
        """SIGTERM every group the page started, SIGKILL what is left after 15 s."""
        for sig, grace in ((signal.SIGTERM, 15.0), (signal.SIGKILL, 5.0)):
            alive = [g for g in self.groups if _signal(g, sig)]
            deadline = time.monotonic() + grace
            while alive and time.monotonic() < deadline:
                time.sleep(0.1)
                alive = [g for g in alive if _signal(g, 0)]
            if not alive:
                return


def _signal(group: int, sig: int) -> bool:
    try:
        os.killpg(group, sig)
    except (ProcessLookupError, PermissionError):
        return False
    return True


def _lines(out: Path) -> list[str]:
    return out.read_text(encoding="utf-8", errors="replace").replace("\r", "\n").split("\n")


def _tail(out: Path, n: int = 40) -> str:
    return "\n".join(_lines(out)[-n:])


def _run_block(page: _Page, block: Block) -> None:
    if block.kind == "file":
        (page.folder / str(block.file)).write_text(block.text, encoding="utf-8")
        return
    if block.kind == "sh":
        status, out = page.run("set -e\n" + block.text, block.timeout_s)
        assert status == 0, (f"{block.where}: the example ended with status {status}:\n"
                             f"{block.text}\n--- it printed:\n{_tail(out)}")
        return
    deadline = time.monotonic() + block.timeout_s
    for cmd in block.commands:
        status, out = page.run(cmd.text, max(deadline - time.monotonic(), 1.0))
        where = f"{block.page}:{cmd.line}"
        if cmd.background:
            if cmd.expected:  # what it prints once it is up: wait for it (bounded)
                until = time.monotonic() + BACKGROUND_WAIT_S
                while not output_matches([*cmd.expected, "…"], _lines(out), block.rel):
                    assert time.monotonic() < until, (
                        f"{where}: `{cmd.text}` did not print what the page shows within "
                        f"{BACKGROUND_WAIT_S:g} s:\n" + "\n".join(cmd.expected)
                        + f"\n--- it printed:\n{_tail(out)}")
                    time.sleep(0.2)
            continue
        assert status == 0 or shows_error(cmd.expected), (
            f"{where}: `{cmd.text}` ended with status {status}:\n{_tail(out)}")
        if cmd.expected:
            got = _lines(out)
            assert output_matches(cmd.expected, got, block.rel), (
                f"{where}: `{cmd.text}` printed other than the page shows.\n--- the page:\n"
                + "\n".join(cmd.expected) + "\n--- printed:\n" + "\n".join(got))


@pytest.mark.slow
@pytest.mark.timeout(900)  # a page's blocks have timeouts of their own (docexamples)
@pytest.mark.parametrize("path", _pages(), ids=_name)
def test_page_examples(path: Path, tmp_path: Path, request: pytest.FixtureRequest) -> None:
    """Every example of one page runs and prints what the page shows."""
    name = _name(path)
    first = len(RESULTS)
    folder, logs = tmp_path / "work", tmp_path / "logs"
    folder.mkdir()
    logs.mkdir()
    env = _environment(tmp_path, name)
    page = _Page(folder, env, logs)
    try:
        for block in read_blocks(path, name):
            if block.kind == "file":
                _run_block(page, block)
                continue
            reason = block.skip
            if reason is None and "PLUGCELL_DATA" in block.text and "PLUGCELL_DATA" not in env:
                reason = "needs the reference data (shared/data, $PLUGCELL_DATA): absent here"
            if reason is not None:
                RESULTS.append((block.where, "skipped", reason, 0.0))
                continue
            t0 = time.monotonic()
            try:
                _run_block(page, block)
            except BaseException:
                RESULTS.append((block.where, "failed", "", time.monotonic() - t0))
                raise
            RESULTS.append((block.where, "passed", "", time.monotonic() - t0))
    finally:
        page.stop()
        # the page's counts travel with its report (to the summary, from any xdist worker)
        request.node.user_properties.append(("docs_examples", RESULTS[first:]))
