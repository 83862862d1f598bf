"""Test-suite wide setup: the shared helpers of ``tests/support`` are importable by name,
and every property-based test is deterministic (hypothesis draws from a fixed seed per
test and keeps no example database: the same examples on every machine and run)."""

import sys
from pathlib import Path

from hypothesis import settings

sys.path.insert(0, str(Path(__file__).resolve().parent / "support"))

settings.register_profile("plugcell", derandomize=True, database=None)
settings.load_profile("plugcell")
