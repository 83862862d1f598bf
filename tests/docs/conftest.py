"""The docs' tests' helpers (``docexamples``) are importable by name.  The count of the
docs' examples in pytest's summary is in ``tests/conftest.py``: under pytest-xdist only
the top conftest's hooks run in the controller, which writes the summary."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
