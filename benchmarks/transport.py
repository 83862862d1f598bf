"""Transport benchmark of thesis 5.3 (Table 5-5).

``python benchmarks/transport.py [--quick] [--json] [--output FILE]``.

Same as ``plugcell bench transport``; the implementation is ``plugcell.apps.bench.transport``.
"""

import sys

from plugcell.apps.bench.transport import main

if __name__ == "__main__":
    sys.exit(main())
