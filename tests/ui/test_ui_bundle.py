"""The 3-D library of the UI (three.js, bundled by esbuild at build time, committed under
``static/vendor``) is the one the lock file names, carries its licence, and is exactly what
the build script makes from the lock file (rebuilt when ``apps/ui/web/node_modules`` is
installed: ``make test`` runs ``npm ci`` there)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from plugcell.apps.ui.app import STATIC

WEB = STATIC.parent / "web"
VENDOR = STATIC / "vendor"


def _locked(package: str) -> str:
    lock = json.loads((WEB / "package-lock.json").read_text())
    return lock["packages"][f"node_modules/{package}"]["version"]


def test_the_bundle_is_the_locked_three_with_its_licence() -> None:
    version = _locked("three")
    manifest = json.loads((WEB / "package.json").read_text())
    assert manifest["devDependencies"]["three"] == version  # exact, no range
    head = (VENDOR / "three.bundle.js").read_text()[:200]
    assert head.startswith(f"/* three.js {version} (MIT")
    licence = (VENDOR / "three.LICENSE").read_text()
    assert "The MIT License" in licence and "three.js authors" in licence


def test_the_page_loads_nothing_from_elsewhere() -> None:
    remote = re.compile(r"""(src=|href=|from\s*|import\s*\(\s*)["'](https?:)?//""")
    for page in [STATIC / "index.html", *sorted((STATIC / "js").glob("*.js"))]:
        assert not remote.search(page.read_text()), page
    assert 'from "../vendor/three.bundle.js"' in (STATIC / "js" / "view3d.js").read_text()


@pytest.mark.slow
@pytest.mark.skipif(not (WEB / "node_modules" / "three").is_dir() or not shutil.which("node"),
                    reason="apps/ui/web/node_modules not installed (make test runs npm ci)")
def test_the_committed_bundle_is_what_the_build_makes(tmp_path: Path) -> None:
    subprocess.run(["node", "build.mjs", str(tmp_path)], cwd=WEB, check=True, timeout=120)
    for name in ("three.bundle.js", "three.LICENSE"):
        assert (tmp_path / name).read_bytes() == (VENDOR / name).read_bytes(), (
            f"static/vendor/{name} is stale: cd {WEB} && npm ci && npm run build")
