"""``python -m plugcell.services.robot``: the robot service's legacy entry (service.main)."""

import sys

from plugcell.services.robot.service import main

sys.exit(main())
