"""plugcell.apps.reproduce — the thesis's experiments recomputed (``plugcell reproduce``).

* :mod:`.identification_8_1` — thesis 8.1, Table 8-1: simulated identification;
* :mod:`.models_8_2` — thesis 8.2, Tables 8-2..8-4: models 1–5 on the digital twin;
* :mod:`.compensation_8_3` — thesis 8.3, two-stage error compensation on the twin
  (:mod:`plugcell.sim.twin_cell`); :mod:`.pages_8_3` writes its table, figures and page.

The command line is :mod:`plugcell.apps.commands.reproduce`.
"""
