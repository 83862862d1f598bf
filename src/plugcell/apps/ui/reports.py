"""The calibration report and the reproduced thesis figures, listed for the UI.

``plugcell reproduce … --out-dir docs/results`` writes the repository's pages and figures
there (``8.1.md``, ``8.3-fig-8-12.png`` …) and ``plugcell calibrate --report`` writes a
self-contained HTML report.  The UI lists them and serves them read-only: only
files inside the folders given here, only the suffixes below, never a path that
leaves them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

SUFFIXES = {".md": "text/markdown; charset=utf-8", ".png": "image/png",
            ".html": "text/html; charset=utf-8", ".json": "application/json",
            ".svg": "image/svg+xml", ".csv": "text/csv; charset=utf-8"}

__all__ = ["ReportFiles", "default_docs_dir"]


def default_docs_dir() -> Path | None:
    """``docs/`` of the source tree plugcell runs from, if there is one."""
    import plugcell

    candidate = Path(plugcell.__file__).resolve().parents[2] / "docs"
    return candidate if candidate.is_dir() else None


@dataclass
class ReportFiles:
    """The documents the UI may show: ``docs/results/*`` and named calibration reports."""

    docs: Path | None = None
    reports: list[Path] = field(default_factory=list)

    def _results(self) -> Path | None:
        return self.docs / "results" if self.docs is not None else None

    def listing(self) -> list[dict[str, Any]]:
        """Calibration reports first, then the reproduced results grouped by section."""
        out: list[dict[str, Any]] = []
        for i, path in enumerate(self.reports):
            if path.is_file():
                out.append({"group": "calibration report", "name": path.name,
                            "url": f"/reports/calibration/{i}", "kind": "html"})
        results = self._results()
        if results is not None and results.is_dir():
            for path in sorted(results.iterdir()):
                if path.suffix in SUFFIXES and path.is_file():
                    section = path.name.split("-", 1)[0].removesuffix(path.suffix)
                    out.append({"group": f"results {section}", "name": path.name,
                                "url": f"/reports/results/{path.name}",
                                "kind": path.suffix.lstrip(".")})
        return out

    def calibration(self, index: int) -> Path | None:
        if 0 <= index < len(self.reports) and self.reports[index].is_file():
            return self.reports[index]
        return None

    def result(self, name: str) -> Path | None:
        """The file ``docs/results/<name>`` if it is a plain file there with a known suffix."""
        results = self._results()
        if results is None or any(c in name for c in "/\\\0") or name.startswith("."):
            return None
        path = (results / name).resolve()
        if path.parent != results.resolve() or path.suffix not in SUFFIXES:
            return None
        return path if path.is_file() else None
