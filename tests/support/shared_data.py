"""Where the reference data of ``../shared/data`` are (CI has ``shared/`` beside the repo).

``PLUGCELL_SHARED`` (a ``shared`` folder) overrides the default — handy in a git
worktree that does not sit beside ``shared/``.  Tests that need the data skip
cleanly when it is absent.
"""

from __future__ import annotations

import os
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def shared_dir() -> Path:
    env = os.environ.get("PLUGCELL_SHARED")
    return Path(env) if env else REPO.parent / "shared"


DATA = shared_dir() / "data"
URDF_DIR = DATA / "urdf"
IPA_DIR = DATA / "ipa-robot-accuracy"
UR_XACRO = URDF_DIR / "ur_description" / "urdf" / "ur.urdf.xacro"
FANUC_XACRO = URDF_DIR / "fanuc" / "fanuc_m20ia_support" / "urdf" / "m20ia.xacro"
STAUBLI_XACRO = URDF_DIR / "staubli" / "staubli_tx2_60_support" / "urdf" / "tx2_60l.xacro"
