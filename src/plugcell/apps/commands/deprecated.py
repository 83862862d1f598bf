"""Old names kept working: an option, a command or a service kind renamed to end a clash
of meanings (issue #33) still works under its old name, with one warning line naming the
new one (the list of renames: docs/framework.md, "Renamed in issue #33")."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any


def warn_renamed(old: str, new: str) -> None:
    """The one warning line of a deprecated name: ``plugcell: warning: OLD is deprecated:
    use NEW`` on stderr."""
    print(f"plugcell: warning: {old} is deprecated: use {new}", file=sys.stderr)


class DeprecatedName(argparse.Action):
    """Store like the new option; used under its old name, warn on stderr once per use.

    Give the new name first: ``p.add_argument("--payload-kg", "--payload",
    action=DeprecatedName, old=("--payload",), type=float)``.
    """

    def __init__(self, option_strings: Sequence[str], dest: str, *, old: Sequence[str],
                 **kwargs: Any) -> None:
        super().__init__(option_strings, dest, **kwargs)
        self.old = tuple(old)
        self.new = next(o for o in option_strings if o not in self.old)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        if option_string in self.old:
            warn_renamed(option_string, self.new)
        setattr(namespace, self.dest, values)
