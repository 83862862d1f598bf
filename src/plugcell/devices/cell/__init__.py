"""The cell controller service (thesis 7.6): one service composed of small parts.

* :mod:`.service` — ``CellController``: discovery, its commands, the wiring of it all;
* :mod:`.wiring` — wires, the wiring file and the keeper that re-applies them;
* :mod:`.tasks` — a task (any command of any service) checked against its declaration;
* :mod:`.runs` — robot programs run sequentially or concurrently;
* :mod:`.monitor` — every process of the cell, and the queue of each shared device;
* :mod:`.journal_tail` — the journals of this host read incrementally (queued processes);
* :mod:`.feed` — what the web UI hears: the activity log and batched changes.
"""
