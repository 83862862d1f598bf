"""A package's names imported on first use (``plugcell.lazy``): what importing a
package's module costs, and the package's names as before."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from plugcell.lazy import exports


@pytest.fixture
def package(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    """A package ``lazypkg`` with two modules re-exported lazily; ``loaded`` records the
    modules imported."""
    root = tmp_path / "lazypkg"
    root.mkdir()
    (root / "__init__.py").write_text(
        "from plugcell.lazy import exports\nloaded = []\n"
        "__getattr__, __dir__, __all__ = exports(__name__, "
        "{'one': ('ONE', 'first'), 'two': ('Two',)})\n")
    (root / "one.py").write_text("from lazypkg import loaded\nloaded.append('one')\n"
                                 "ONE = 1\ndef first():\n    return 'first'\n")
    (root / "two.py").write_text("from lazypkg import loaded\nloaded.append('two')\n"
                                 "class Two:\n    pass\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "lazypkg"
    for name in [m for m in sys.modules if m == "lazypkg" or m.startswith("lazypkg.")]:
        del sys.modules[name]


def test_a_name_imports_its_module_only_when_used(package: str) -> None:
    import lazypkg

    assert lazypkg.loaded == []
    from lazypkg import ONE, first

    assert (ONE, first()) == (1, "first") and lazypkg.loaded == ["one"]
    assert lazypkg.ONE == 1 and "ONE" in vars(lazypkg)  # kept: a plain attribute now
    assert lazypkg.loaded == ["one"]
    assert lazypkg.__all__ == ["ONE", "Two", "first"]
    assert {"ONE", "Two", "first", "loaded"} <= set(dir(lazypkg))
    assert lazypkg.loaded == ["one"]  # dir() imports nothing
    namespace: dict[str, object] = {}
    exec("from lazypkg import *", namespace)
    assert namespace["Two"].__name__ == "Two" and lazypkg.loaded == ["one", "two"]


def test_an_unknown_name_is_an_attribute_error(package: str) -> None:
    import lazypkg

    with pytest.raises(AttributeError, match="module 'lazypkg' has no attribute 'Three'"):
        _ = lazypkg.Three
    with pytest.raises(ImportError, match="cannot import name 'Three'"):
        exec("from lazypkg import Three", {})
    assert lazypkg.loaded == []


def test_a_name_listed_twice_is_refused() -> None:
    with pytest.raises(ValueError, match="pkg: 'A' listed for both 'one' and 'two'"):
        exports("pkg", {"one": ("A",), "two": ("B", "A")})


@pytest.mark.parametrize("package", ["plugcell.calibration", "plugcell.compensation",
                                     "plugcell.compensation.tracking", "plugcell.metrology"])
def test_every_name_of_the_lazy_packages_is_there(package: str) -> None:
    """Each listed name is what its module defines, under the package (a name its module
    lacks raises here), and ``__all__`` lists every one."""
    import importlib

    pkg = importlib.import_module(package)
    listed = [(module, name) for module, names in pkg._NAMES.items() for name in names]
    assert sorted(pkg.__all__) == sorted(name for _, name in listed)
    for module, name in listed:
        assert getattr(pkg, name) is getattr(importlib.import_module(f"{package}.{module}"),
                                             name), f"{package}.{name}"


def test_the_link_process_does_not_import_scipy() -> None:
    """The robot's link process (its own child) needs no SciPy: importing its module
    imports none (before, the rate limiter's package pulled in SciPy through the
    compensation and calibration packages: ~2 s of start-up)."""
    code = ("import sys, plugcell.devices.robot.stream.process\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('scipy', 'sklearn')))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"
