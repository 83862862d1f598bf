"""Helpers of the robot-program tests: models from PARAMS results, reachable poses, the
round trips every dialect passes, a refused edit named where it stands."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from plugcell.compensation import IdentifiedModel, NominalModel
from plugcell.io.robots import load_robot
from plugcell.io.units import notation_from_pose, pose_from_notation
from plugcell.sim.twin.campaign import working_volume_joints
from plugcell.sim.twin.profile import TwinProfile

FIXTURES = Path(__file__).parent / "fixtures"
H4 = load_robot("smart_h4")
#: 40 joint configurations in the working volume (seeded)
WORK_Q = working_volume_joints(H4, TwinProfile.load("smart_h4"), 40, np.random.default_rng(7))


def model_for(result):
    """``TOOL → IdentifiedModel`` of a calibration result (the command's factory)."""
    return lambda tool: IdentifiedModel(result.model, tool)


def poses_in(notation: str, base_values, tool_values, k: np.ndarray) -> np.ndarray:
    """Reachable target numbers in ``notation``: the nominal TCP at ``WORK_Q[k]``
    with the tool, expressed in the base frame."""
    B = pose_from_notation(np.asarray(base_values, float), notation)
    tool = pose_from_notation(np.asarray(tool_values, float), notation)
    T = np.linalg.inv(B) @ NominalModel(H4, tool).pose(WORK_Q[k])
    ref = np.zeros((len(k), 7 if notation == "abb" else 6))
    if notation == "abb":
        ref[:, 3] = 1.0
    return notation_from_pose(T, notation, ref)


def assert_equals_plugcell_compensate(program, fr, result, bases=None, tools=None,
                                      payload_kg=36.0):
    """Every compensated pose target's joints give, on the identified model, the pose
    ``plugcell compensate``'s path (filter_program with --user-frame and --tool, and the IK
    seed of the program's arm configuration when it is not home's) gives, to 1e-9 mm; and
    the model reaches the program's target there (1e-6 m)."""
    from plugcell.compensation import filter_program
    from plugcell.kinematics.rotations import matrix_to_angles

    frames = {**program.frames, **(bases or {})}
    tls = {**program.tools, **(tools or {})}
    n = 0
    for r in fr.reports:
        t = r.target
        if not r.compensated or t.kind != "pose":
            continue
        P = pose_from_notation(r.before, t.notation)
        U = frames[t.base] if t.base is not None else np.eye(4)
        model = IdentifiedModel(result.model, tls[t.tool])
        ref = filter_program(model, P[None, :3, 3], matrix_to_angles(P[None, :3, :3], "zyz"),
                             "zyz", user_frame=U, payload_kg=payload_kg,
                             seed=None if r.seed is None else r.seed[None])
        got = model.pose(r.q[None], payload_kg)
        want = model.pose(ref.q, payload_kg)
        assert np.abs(got[:, :3, 3] - want[:, :3, 3]).max() * 1e3 < 1e-9, t.name
        assert np.abs((U @ P)[:3, 3] - got[0, :3, 3]).max() < 1e-6, t.name
        n += 1
    return n


def assert_nominal_round_trip(params: Path, program: Path, out: Path, *options: str) -> None:
    """``plugcell compensate`` with a nominal model writes ``program`` back byte for byte,
    its joint targets kept or compensated (``options``: the frames it needs)."""
    from plugcell.apps.cli import main

    for mode in ("keep", "compensate"):
        assert main(["compensate", "--params", str(params), "--program", str(program),
                     "--out", str(out), "--joint-targets", mode, *options]) == 0
        assert out.read_bytes() == program.read_bytes()


def assert_generated_round_trip(result, folder: Path, files: dict[str, str], **frames):
    """A generated program (``files``: name → text, the main file first) written to
    ``folder``, read and filtered on ``result``'s (nominal) model: every target ok, and
    the rendered files are the texts byte for byte.  ``frames``: ``bases``, ``tools`` of
    :func:`~plugcell.io.programs.filter.filter_targets`.  The FilterResult."""
    from plugcell.io.programs import read_program
    from plugcell.io.programs.filter import filter_targets

    for name, text in files.items():
        (folder / name).write_bytes(text.encode())
    program, _ = read_program(folder / next(iter(files)))
    fr = filter_targets(program, model_for(result), payload_kg=36.0, **frames)
    assert all(r.ok for r in fr.reports)
    assert program.render(fr.edits) == list(files.values())
    return fr


def assert_edit_refused(program: Path, copy: Path, old: str, new: str, message: str) -> None:
    """``program`` with its first ``old`` replaced by ``new``, written to ``copy``, is
    refused: a ProgramError with ``message`` at ``<copy's name>:<line>:<column>``."""
    import pytest

    from plugcell.io.programs import ProgramError, read_program

    text = program.read_bytes().decode()
    assert old in text
    copy.write_bytes(text.replace(old, new, 1).encode())
    with pytest.raises(ProgramError) as ei:
        read_program(copy)
    s = str(ei.value)
    assert f"{copy.name}:" in s and message in s, s
    line, col = s.split(f"{copy.name}:")[1].split(":")[:2]
    assert int(line) > 0 and int(col) > 0
