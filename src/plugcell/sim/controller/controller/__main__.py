"""``python -m plugcell.sim.controller.controller``: the old name of
``python -m plugcell.sim.controller`` (:mod:`plugcell.apps.commands.sim_controller`)."""

from __future__ import annotations

import sys

from plugcell.apps.commands.sim_controller import main

if __name__ == "__main__":
    sys.exit(main())
