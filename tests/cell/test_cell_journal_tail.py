"""The controller's journal reader under its worker thread (services/cell/journal_tail.py).

The controller polls the journals in a worker thread; closing the controller while
a poll is under way once closed a SQLite connection under it and crashed the
process (found by the test suite running on uvloop).  ``close`` now waits for the
poll; here a thread polls without pause while the main thread closes over and over.
"""

from __future__ import annotations

import threading
import time

from plugcell.devices.cell.journal_tail import JournalTail
from plugcell.framework.journal import Journal, journal_dir


def test_close_while_a_poll_runs_in_another_thread(tmp_path):
    cell = "tail"
    journal = Journal(journal_dir(cell, tmp_path) / "DEV.sqlite", "DEV")
    for i in range(5000):
        journal.record_process(
            sender="A", identifier=i + 1, sender_instance="a", recipient_instance="d",
            command="Work", option="", command_type="NoData", input_summary="",
            received_ns=i, state="Queued")
        journal.record_update("A", i + 1, 1, "Completed", "", "")
    journal.commit()
    tail = JournalTail(cell, tmp_path)
    stop = threading.Event()
    seen: list[int] = []
    errors: list[BaseException] = []

    def poll_forever() -> None:
        try:
            while not stop.is_set():
                processes, _ = tail.poll()
                seen.append(len(processes))
        except BaseException as exc:
            errors.append(exc)

    worker = threading.Thread(target=poll_forever)
    worker.start()
    try:
        for _ in range(300):
            tail.close()  # each close makes the next poll reopen and re-read
            time.sleep(0.0002)
    finally:
        stop.set()
        worker.join(10)
        journal.close()
    assert not errors
    assert seen and max(seen) == 200  # HISTORY rows on each fresh start
