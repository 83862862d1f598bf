"""The packages of plugcell in layers, and no import upward (read with ``ast``, nothing
imported — so an import inside a function counts as much as one at the top).

====================  ========================================================  ===================
layer                 packages                                                  may import
====================  ========================================================  ===================
base                  lazy (a package's names imported on first use)            nothing
math                  kinematics, metrology, calibration, compensation,         math, base
                      motion
io                    io (file formats: robots, URDF, measurements, units)      math, io, base
framework             framework (Zenoh, the service base, the journal)          framework, base
pdl                   pdl (the robot language: parser, checker, interpreter)    math, io, pdl, base
devices               devices (camera, drill, robot, tracker, compute,          all but sim
                      cell, opcua)                                              and apps
sim                   sim (twin, simulated controller, drivers, world)          all but apps
apps                  apps (cli, commands, ui, demo, reproduce, bench), every   everything
                      ``__main__`` module (a program, not a library)
====================  ========================================================  ===================

A module named in a string (for importlib, or run as ``-m``) counts as an import.
The math never reads a file, speaks Zenoh or knows a device; the framework knows no
device; the robot language knows neither the framework nor a device; nothing below the
apps calls a command line or is one (no ``main``, no ``if __name__ == "__main__"``: a
program lives in ``apps``, run by ``python -m`` of a ``__main__`` module).  A device
declares its driver interface and never imports the simulator: a simulated instrument in
``sim`` implements that interface, and
``plugcell serve`` (``apps/kinds.py``) hands a device its simulated driver (the robot:
the launcher of its simulated controller).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
from source_trees import parsed

SRC = Path(__file__).resolve().parents[1] / "src" / "plugcell"

MATH = {"kinematics", "metrology", "calibration", "compensation", "motion"}
#: Modules of the package's top level below every layer: they import nothing of plugcell.
BASE = {"lazy"}
#: What each layer must not import.
FORBIDDEN = {
    "base": {"math", "io", "framework", "pdl", "sim", "devices", "apps"},
    "math": {"io", "framework", "pdl", "sim", "devices", "apps"},
    "io": {"framework", "pdl", "sim", "devices", "apps"},
    "framework": {"math", "io", "pdl", "sim", "devices", "apps"},
    "pdl": {"framework", "sim", "devices", "apps"},
    "sim": {"apps"},
    "devices": {"sim", "apps"},
    "apps": set(),
}


def layer_of(module: str) -> str | None:
    """The layer of ``plugcell.…`` module ``module`` (None: not plugcell's)."""
    parts = module.split(".")
    if parts[0] != "plugcell":
        return None
    if len(parts) == 1:
        return "apps"  # the package itself: its version, nothing else
    top = parts[1]
    if len(parts) == 2 and top in BASE:
        return "base"
    if parts[-1] == "__main__" or top in ("apps", "__main__"):
        return "apps"
    if top in MATH:
        return "math"
    if top in ("io", "framework", "pdl", "devices", "sim"):
        return top
    raise AssertionError(f"{module}: no layer — add its package to tests/test_layering.py")


#: A module named in a string: ``"plugcell.apps.bench.device:BenchService"`` for
#: importlib, ``"-m", "plugcell.sim.controller"`` for a child process.
MODULE_TEXT = re.compile(r"plugcell(?:\.[A-Za-z_]\w*)+(?::[A-Za-z_]\w*)?")


def imports(source: str) -> list[tuple[int, str]]:
    """``(line, module)`` of every absolute import in ``source``, also inside functions,
    and of every module a string names whole (loaded by name, or run as a program)."""
    found = []
    for node in ast.walk(parsed(source)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.append((node.lineno, node.module))
        elif (isinstance(node, ast.Constant) and isinstance(node.value, str)
              and MODULE_TEXT.fullmatch(node.value)):
            found.append((node.lineno, node.value.partition(":")[0]))
    return found


def upward_imports(source: str, module: str) -> list[str]:
    """Every import of ``source`` (module ``module``) its layer forbids."""
    mine = layer_of(module)
    assert mine is not None
    found = []
    for line, target in imports(source):
        theirs = layer_of(target)
        if theirs in FORBIDDEN[mine]:
            found.append(f"{module}:{line} ({mine}) imports {target} ({theirs})")
    return found


def modules() -> list[tuple[str, Path]]:
    out = []
    for path in sorted(SRC.rglob("*.py")):
        parts = path.relative_to(SRC).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out.append((".".join(("plugcell", *parts)), path))
    return out


def test_no_module_imports_upward() -> None:
    offences = [o for module, path in modules()
                for o in upward_imports(path.read_text(encoding="utf-8"), module)]
    assert offences == []


def test_every_package_has_a_layer() -> None:
    for module, _ in modules():
        assert layer_of(module) is not None


@pytest.mark.parametrize(("module", "source", "offence"), [
    ("plugcell.calibration.fit", "from plugcell.io.robots import load_robot\n",
     "plugcell.calibration.fit:1 (math) imports plugcell.io.robots (io)"),
    ("plugcell.kinematics.forward", "def f():\n    import plugcell.framework.codec\n",
     "plugcell.kinematics.forward:2 (math) imports plugcell.framework.codec (framework)"),
    ("plugcell.framework.service", "from plugcell.devices.camera import CameraService\n",
     "plugcell.framework.service:1 (framework) imports plugcell.devices.camera (devices)"),
    ("plugcell.devices.robot.service", "def main():\n    from plugcell.apps.cli import main\n",
     "plugcell.devices.robot.service:2 (devices) imports plugcell.apps.cli (apps)"),
    ("plugcell.sim.twin.robot", "from plugcell.apps.commands.twin import run\n",
     "plugcell.sim.twin.robot:1 (sim) imports plugcell.apps.commands.twin (apps)"),
    ("plugcell.devices.camera", "from plugcell.sim.drivers.camera import SimulatedCamera\n",
     "plugcell.devices.camera:1 (devices) imports plugcell.sim.drivers.camera (sim)"),
    ("plugcell.devices.kinds", 'KINDS = {\n    "bench": "plugcell.apps.bench.device:Bench"}\n',
     "plugcell.devices.kinds:2 (devices) imports plugcell.apps.bench.device (apps)"),
])
def test_a_wrong_import_is_reported(module: str, source: str, offence: str) -> None:
    assert upward_imports(source, module) == [offence]


def test_programs_and_lower_layers_may_import_what_they_need() -> None:
    assert upward_imports("from plugcell.apps.cli import main\n",
                          "plugcell.devices.robot.__main__") == []
    assert upward_imports("from plugcell.kinematics import forward\nimport numpy\n",
                          "plugcell.io.robots") == []
    assert upward_imports("from plugcell.framework.service import GenericDevice\n",
                          "plugcell.devices.camera") == []


#: Libraries of file formats: their schemas are io's (the robot file schema is
#: plugcell.io.robot_schema); the math takes and returns arrays and objects.
FILE_FORMATS = ("msgspec", "tomllib", "tomli_w")


def file_format_imports(source: str, module: str) -> list[str]:
    """Every import of a file-format library by ``source`` (module ``module``)."""
    return [f"{module}:{line} imports {target}" for line, target in imports(source)
            if target.split(".")[0] in FILE_FORMATS]


def test_the_math_parses_no_file_format() -> None:
    offences = [o for module, path in modules() if layer_of(module) == "math"
                for o in file_format_imports(path.read_text(encoding="utf-8"), module)]
    assert offences == []
    assert file_format_imports("def f():\n    from msgspec import convert\n",
                               "plugcell.kinematics.description") == [
        "plugcell.kinematics.description:2 imports msgspec"]


#: Modules outside the apps layer allowed to define a top-level ``main`` (module → why).
#: None: a program is the apps' (``apps/commands/…``, or a ``__main__`` module that calls
#: one), a library below it is imported, never run.
MAIN_ALLOWED: dict[str, str] = {}


def programs(source: str) -> list[str]:
    """What makes ``source`` a program: a top-level ``main`` function, or an
    ``if __name__ == "__main__":`` block."""
    found = []
    for node in parsed(source).body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and node.name == "main":
            found.append(f"def main (line {node.lineno})")
        elif (isinstance(node, ast.If) and isinstance(node.test, ast.Compare)
              and isinstance(node.test.left, ast.Name) and node.test.left.id == "__name__"):
            found.append(f"if __name__ … (line {node.lineno})")
    return found


def test_programs_live_only_in_apps() -> None:
    """No module below the apps defines ``main`` or runs as a program (issue 33): the
    simulated controller's program is ``apps/commands/sim_controller.py``, run by
    ``python -m plugcell.sim.controller`` (a ``__main__`` module, an app)."""
    offences = [f"{module}: {what}" for module, path in modules()
                if layer_of(module) != "apps" and module not in MAIN_ALLOWED
                for what in programs(path.read_text(encoding="utf-8"))]
    assert offences == []
    assert programs("import sys\ndef main():\n    pass\nif __name__ == '__main__':\n"
                    "    sys.exit(main())\n") == ["def main (line 2)", "if __name__ … (line 4)"]
    assert programs("def f():\n    def main():\n        pass\n") == []


@pytest.mark.slow
def test_the_simulated_controller_runs_by_both_program_names() -> None:
    """``python -m plugcell.sim.controller`` and its old name
    ``python -m plugcell.sim.controller.controller`` run the same program (a bad option:
    exit code 2 and the reason)."""
    import subprocess
    import sys

    for module in ("plugcell.sim.controller", "plugcell.sim.controller.controller"):
        run = subprocess.run([sys.executable, "-m", module, "--link-baud", "-5", "--no-world"],
                             capture_output=True, text=True, timeout=60)
        assert run.returncode == 2, (module, run.stderr)
        assert run.stderr.strip() == ("plugcell-controller: error: --link-baud must be 0 or "
                                      "positive, not -5.0")
