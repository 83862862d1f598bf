"""A loaded program: parsed, its libraries resolved, statically checked — immutable.

:class:`Program` is what a controller keeps in its program library; each run of it
is a separate :class:`~.interpreter.Execution` (mutable state).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from types import MappingProxyType

from plugcell.pdl import nodes as n
from plugcell.pdl.checker import ParsedModule, check_program
from plugcell.pdl.errors import LibraryError
from plugcell.pdl.library import find_library, read_source
from plugcell.pdl.parser import parse_module
from plugcell.pdl.printer import format_module
from plugcell.pdl.scope import ModuleScope, VarInfo
from plugcell.pdl.types import LangType

__all__ = ["MAX_MODULES", "Program"]

#: Most files one program may pull in through IMPORT / EXPORTED FROM.
MAX_MODULES = 200

PathLike = str | Path


def _library_of(decl: n.Decl) -> str | None:
    if isinstance(decl, n.Import):
        return decl.path
    if isinstance(decl, n.Routine | n.VarDecl):
        return decl.exported_from
    return None


def _collect(main: ParsedModule, library_path: Sequence[Path]) -> dict[str, ParsedModule]:
    parsed: dict[str, ParsedModule] = {main.key: main}
    queue = [main]
    while queue:
        pm = queue.pop(0)
        for decl in pm.module.decls:
            lib = _library_of(decl)
            if lib is None:
                continue
            own = n.key(lib) == n.key(pm.module.name)
            if own and isinstance(decl, n.VarDecl):
                continue
            if own and isinstance(decl, n.Routine):
                raise LibraryError.at(
                    decl.loc,
                    f"ROUTINE {decl.name} EXPORTED FROM {lib}: that is this program; "
                    "write the routine's body here instead",
                )
            try:
                path = find_library(lib, pm.base_dir, library_path, decl.loc)
            except LibraryError:
                if isinstance(decl, n.VarDecl):  # a program we do not have: a plain global
                    continue
                raise
            k = str(path)
            pm.links[id(decl)] = k
            if k not in parsed:
                if len(parsed) >= MAX_MODULES:
                    raise LibraryError.at(decl.loc, f"more than {MAX_MODULES} library files")
                module = parse_module(read_source(path), str(path))
                parsed[k] = ParsedModule(k, module, path.parent)
                queue.append(parsed[k])
    return parsed


class Program:
    """A checked program and its libraries.  Build with :meth:`load` or :meth:`from_source`.

    Raises :class:`~.errors.ProgramError` (file, line, message) for anything wrong
    in the program or a library it uses.
    """

    def __init__(self, scopes: Mapping[str, ModuleScope], main_key: str) -> None:
        for scope in scopes.values():  # read-only from now on
            scope.freeze()
        self._scopes = MappingProxyType(dict(scopes))
        self._main_key = main_key
        main = scopes[main_key]
        settable = {k: v for k, v in main.externals.items() if v.settable}
        settable.update({k: v for k, v in main.globals.items() if v.settable})
        self._settable = MappingProxyType(settable)

    # ----------------------------------------------------------------- construction
    @classmethod
    def load(cls, path: PathLike, library_path: Sequence[PathLike] = ()) -> Program:
        """Load ``path`` (a ``.pdl`` file) and the libraries it imports."""
        p = Path(path).resolve()
        text = read_source(p)
        return cls._build(text, str(p), p.parent, library_path, key=str(p))

    @classmethod
    def from_source(
        cls,
        text: str,
        file: str = "<string>",
        library_path: Sequence[PathLike] = (),
        base_dir: PathLike | None = None,
    ) -> Program:
        """Build from source text; ``file`` names it in error messages and IMPORTs
        are resolved relative to ``base_dir`` and ``library_path``."""
        base = Path(base_dir) if base_dir is not None else None
        return cls._build(text, file, base, library_path, key=file)

    @classmethod
    def _build(
        cls,
        text: str,
        file: str,
        base_dir: Path | None,
        library_path: Sequence[PathLike],
        key: str,
    ) -> Program:
        if isinstance(library_path, str | Path):
            library_path = [library_path]
        search = [Path(p) for p in library_path]
        main = ParsedModule(key, parse_module(text, file), base_dir)
        parsed = _collect(main, search)
        scopes = check_program(parsed, key)
        return cls(scopes, key)

    # ----------------------------------------------------------------- queries
    @property
    def name(self) -> str:
        """The PROGRAM's name."""
        return self.module.name

    @property
    def file(self) -> str:
        return self.module.file

    @property
    def module(self) -> n.Module:
        """The main program's syntax tree."""
        return self._scopes[self._main_key].module

    @property
    def main_key(self) -> str:
        return self._main_key

    @property
    def scopes(self) -> Mapping[str, ModuleScope]:
        """Every module (program and libraries) by key (resolved path)."""
        return self._scopes

    @property
    def libraries(self) -> tuple[str, ...]:
        """Files of the libraries the program uses."""
        return tuple(k for k in self._scopes if k != self._main_key)

    @property
    def variables(self) -> Mapping[str, LangType]:
        """Variables a service may set (``Execution.post``): the service variables
        (``ext_cmd_finished`` …) and the program's global variables."""
        return MappingProxyType({v.name: v.type for v in self._settable.values()})

    def variable(self, name: str) -> VarInfo:
        """The settable variable ``name`` (case-insensitive) or ``KeyError`` saying why."""
        info = self._settable.get(n.key(name))
        if info is None:
            raise KeyError(f"{self.name} has no variable {name} that services may set")
        return info

    def source(self) -> str:
        """The main program, pretty-printed."""
        return format_module(self.module)

    def __repr__(self) -> str:
        return f"Program({self.name!r}, file={self.file!r}, libraries={len(self.libraries)})"
