"""Test-suite wide setup: the shared helpers of ``tests/support`` are importable by name."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent / "support"))
