"""The null journal of a service that keeps none has the journal's interface, no more."""

from __future__ import annotations

import inspect

import pytest

from plugcell.framework.journal import Journal, NullJournal


def _public_methods(cls: type) -> dict[str, inspect.Signature]:
    return {
        name: inspect.signature(member)
        for name, member in vars(cls).items()
        if callable(member) and not name.startswith("_")
    }


def test_null_journal_has_every_writing_and_life_cycle_method_of_the_journal() -> None:
    journal = _public_methods(Journal)
    null = _public_methods(NullJournal)
    assert set(null) <= set(journal)
    for name, signature in null.items():
        assert signature.parameters.keys() == journal[name].parameters.keys(), name
    # every method a service calls on its journal exists on the null one
    assert {"record_process", "record_update", "record_rejection", "commit", "recover",
            "close"} <= set(null)


def test_null_journal_records_nothing_and_recovers_nothing() -> None:
    null = NullJournal()
    assert null.enabled is False and Journal.enabled is True
    null.record_update("A", 1, 1, "Completed", "", "")
    null.record_rejection(None, None, None, 0, "bad")
    null.commit()
    assert null.recover("interrupted") == 0
    null.close()


def test_a_misspelt_journal_call_fails_instead_of_doing_nothing() -> None:
    with pytest.raises(AttributeError):
        NullJournal().record_procces  # noqa: B018 — the misspelling is the point
