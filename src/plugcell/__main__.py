import sys

from plugcell.apps.cli import main

sys.exit(main())
