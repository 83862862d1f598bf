"""framework/memory.py: the allocator tuning is on by default on glibc, off on request."""

from __future__ import annotations

import subprocess
import sys

CODE = ("from plugcell.framework.memory import tune_allocator; "
        "print(tune_allocator(), tune_allocator())")


def _run(env_value: str | None) -> str:
    import os

    env = {k: v for k, v in os.environ.items() if k != "PLUGCELL_MALLOC"}
    if env_value is not None:
        env["PLUGCELL_MALLOC"] = env_value
    return subprocess.run([sys.executable, "-c", CODE], env=env, capture_output=True,
                          text=True, check=True, timeout=60).stdout.split()


def test_tuned_once_per_process_and_left_alone_on_request():
    import platform

    tuned = _run(None)
    assert tuned[0] == tuned[1]  # idempotent
    if platform.system() == "Linux" and platform.libc_ver()[0] == "glibc":
        assert tuned == ["True", "True"]
    assert _run("default") == ["False", "False"]
