"""How big the device classes are: callables through each service kind's MRO, and the
lines of every class in ``framework/`` and ``devices/`` (issue #33).

Devices are composed, not derived: a device is a small declaration plus a driver,
hosted by one framework object (``GenericDevice``), so no device class carries more than
:data:`GOAL_CALLABLES` callables through its MRO — asserted for every kind.  No class
has more than :data:`GOAL_LINES` lines, except the few listed in :data:`LINES_CEILING`,
a ratchet: such a class may shrink (lower its ceiling in the same change), never grow.

Print the table: ``.venv/bin/python tests/test_class_sizes.py``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
from source_trees import parsed

from plugcell.apps.kinds import KINDS, load_kind
from plugcell.framework.participant import Participant
from plugcell.framework.service import GenericDevice

SRC = Path(__file__).resolve().parents[1] / "src" / "plugcell"

GOAL_CALLABLES = 40
GOAL_LINES = 400

#: "path:Class" → the most lines it may have today (only classes over GOAL_LINES).
LINES_CEILING = {
}


def callables_through_mro(cls: type) -> int:
    """Distinct names of methods and properties ``cls`` has, its bases' included."""
    return len({name for c in cls.__mro__ if c is not object for name, value in vars(c).items()
                if callable(value) or isinstance(value, property | classmethod | staticmethod)})


def class_lines() -> dict[str, int]:
    """``"path:Class"`` (path under src/plugcell) → lines, for framework/ and devices/."""
    out = {}
    for package in ("framework", "devices"):
        for path in sorted((SRC / package).rglob("*.py")):
            for node in ast.walk(parsed(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.ClassDef):
                    key = f"{path.relative_to(SRC).as_posix()}:{node.name}"
                    out[key] = node.end_lineno - node.lineno + 1  # type: ignore[operator]
    return out


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_no_device_kind_carries_more_than_the_goal_through_its_mro(kind: str) -> None:
    n = callables_through_mro(load_kind(kind))
    assert n <= GOAL_CALLABLES, f"{kind}: {n} callables through the MRO"


def test_the_host_holds_its_participant_and_carries_no_more_than_the_goal() -> None:
    """The framework object that hosts a device is composed too: it holds a Participant
    (``service.participant``) instead of deriving from one."""
    assert not issubclass(GenericDevice, Participant)
    assert callables_through_mro(GenericDevice) <= GOAL_CALLABLES


def test_no_class_in_framework_or_devices_grows_past_its_ceiling() -> None:
    over = {k: n for k, n in class_lines().items() if n > LINES_CEILING.get(k, GOAL_LINES)}
    assert over == {}


def test_the_ceilings_are_not_stale() -> None:
    """A ceiling names a class that exists and is still over the goal."""
    lines = class_lines()
    assert {k for k in LINES_CEILING if lines.get(k, 0) <= GOAL_LINES} == set()


def test_the_count_sees_inherited_methods() -> None:
    class Base:
        def a(self) -> None: ...

        @property
        def b(self) -> int:
            return 1

    class Child(Base):
        def c(self) -> None: ...

    assert callables_through_mro(Child) == 3


if __name__ == "__main__":
    print(f"{'kind':14} {'class':18} callables-through-MRO (goal ≤ {GOAL_CALLABLES})")
    for kind in sorted(KINDS):
        cls = load_kind(kind)
        print(f"{kind:14} {cls.__name__:18} {callables_through_mro(cls)}")
    for cls in (GenericDevice, Participant):
        print(f"{'(framework)':14} {cls.__name__:18} {callables_through_mro(cls)}")
    print(f"\nlargest classes in framework/ and devices/ (goal ≤ {GOAL_LINES} lines)")
    for key, n in sorted(class_lines().items(), key=lambda kv: -kv[1])[:10]:
        print(f"{n:5}  {key}")
