"""Parsers of the ``--param KEY=VALUE`` values services declare in their ``params``."""

from __future__ import annotations


def flag(text: str) -> bool:
    """``--param sim=true``: a boolean parameter (1/true/yes/on, 0/false/no/off/empty)."""
    value = text.strip().lower()
    if value in ("1", "true", "yes", "on"):
        return True
    if value in ("0", "false", "no", "off", ""):
        return False
    raise ValueError(f"expected true or false, not {text!r}")
