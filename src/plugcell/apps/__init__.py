"""plugcell.apps — the programs: what a person runs, built on every layer below.

* :mod:`.cli` and :mod:`.commands` — the ``plugcell`` command and its sub-commands;
* :mod:`.ui` — the web UI (``plugcell ui``);
* :mod:`.demo` — ``plugcell demo``: the thesis's chapter 8 over services;
* :mod:`.reproduce` — the thesis's experiments recomputed (``plugcell reproduce``);
* :mod:`.bench` — the speed measurements behind ``plugcell bench`` and ``benchmarks/``.

Nothing below this package imports it (``tests/test_layering.py``).
"""
