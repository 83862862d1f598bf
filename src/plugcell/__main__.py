import sys

from plugcell.cli import main

sys.exit(main())
