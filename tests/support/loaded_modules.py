"""Which modules a piece of code loads, seen from a fresh interpreter: how the tests check
that pure math imports no twin, framework or files, and that a parser stays light."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Sequence


def modules_loaded_by(code: str, packages: Sequence[str]) -> list[str]:
    """The modules of ``packages`` (each a package or module, with its submodules) that a
    fresh ``python -c`` has loaded after running ``code``, sorted."""
    script = (
        "import json, sys\n"
        f"{code}\n"
        f"packages = {tuple(packages)!r}\n"
        "print(json.dumps(sorted(m for m in sys.modules\n"
        "                        if any(m == p or m.startswith(p + '.') for p in packages))))\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         check=True, timeout=60)
    return json.loads(out.stdout)
