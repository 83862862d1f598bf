"""Finding and reading program and library files.

``IMPORT 'name'`` and ``… EXPORTED FROM name`` look for ``name`` (``name.pdl`` when
it has no suffix) first next to the importing file, then in each directory of the
library search path, and last in the programs shipped with plugcell
(``plugcell/pdl/programs``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from plugcell.pdl.errors import LibraryError, Location, ParseError

__all__ = ["BUILTIN_LIBRARY", "find_library", "read_source"]

#: Programs and libraries shipped with plugcell.
BUILTIN_LIBRARY = Path(__file__).resolve().parent / "programs"
SUFFIX = ".pdl"


def read_source(path: Path) -> str:
    """A source file as text; not UTF-8 → :class:`~.errors.ParseError` at the bad line."""
    data = path.read_bytes()
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise ParseError(str(path), line, f"not UTF-8 text (byte {data[exc.start]:#04x})") from None


def _candidates(name: str) -> list[str]:
    if Path(name).suffix:
        return [name]
    return [name + SUFFIX, name.lower() + SUFFIX, name.upper() + SUFFIX]


def find_library(
    name: str, base_dir: Path | None, search_path: Sequence[Path], where: Location
) -> Path:
    """Resolve a library reference or raise :class:`~.errors.LibraryError` at ``where``."""
    if not name.strip():
        raise LibraryError.at(where, "empty library name")
    dirs: list[Path] = []
    if base_dir is not None:
        dirs.append(base_dir)
    dirs.extend(Path(p) for p in search_path)
    dirs.append(BUILTIN_LIBRARY)
    tried: list[str] = []
    for d in dirs:
        for candidate in _candidates(name):
            path = Path(candidate) if Path(candidate).is_absolute() else d / candidate
            tried.append(str(path))
            if path.is_file():
                return path.resolve()
    shown = ", ".join(dict.fromkeys(tried))
    raise LibraryError.at(where, f"cannot find library '{name}' (looked for {shown})")
