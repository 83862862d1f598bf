"""The five calibration models of thesis 8.2.3 as named configurations.

====  ================  ===========================================================
 no.  name              contents
====  ================  ===========================================================
 1    ``serial``        standard serial robot (eq. 6.3, loop ignored; Schröer 1997):
                        Smart H4 → 30 parameters
 2    ``loop``          the proposed geometric model with the parallelogram (6.2): 34
 3    ``serial+gravity``  1 + gravity deflection G1–G3 (6.31)
 4    ``loop+gravity``  2 + G1–G3: 37
 5    ``full``          4 + payload compliance A, B, C, D (6.40): 52 in the thesis
====  ================  ===========================================================

A robot without a loop uses the serial family (models 2 and 4 equal 1 and 3),
with joint compliance from its described masses where it has masses.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["MODELS", "ModelConfig", "model_config"]


@dataclass(frozen=True)
class ModelConfig:
    """One of the five models of thesis 8.2.3: structure family and which deflections it includes.

    Attributes
    ----------
    number : int
        1–5.
    name : str
        Short name (``serial``, ``loop``, ``serial+gravity``, ``loop+gravity``, ``full``).
    family : str
        ``"serial"`` (eq. 6.3) or ``"loop"`` (6.2).
    gravity : bool
        Includes the gravity deflection G1–G3 (6.31).
    payload : bool
        Includes the payload compliance A, B, C, D (6.40).
    title : str
        One-line description.
    """

    number: int
    name: str
    family: str
    gravity: bool
    payload: bool
    title: str

    def as_dict(self) -> dict[str, object]:
        """The fields as a JSON-ready dict."""
        return {"number": self.number, "name": self.name, "family": self.family,
                "gravity": self.gravity, "payload": self.payload, "title": self.title}


MODELS: tuple[ModelConfig, ...] = (
    ModelConfig(1, "serial", "serial", False, False,
                "standard serial robot, loop ignored (eq. 6.3)"),
    ModelConfig(2, "loop", "loop", False, False,
                "geometric model with the parallelogram loop (6.2)"),
    ModelConfig(3, "serial+gravity", "serial", True, False,
                "serial robot + gravity deflection G1-G3 (6.31)"),
    ModelConfig(4, "loop+gravity", "loop", True, False,
                "loop model + gravity deflection G1-G3 (6.31)"),
    ModelConfig(5, "full", "loop", True, True,
                "loop + gravity + payload compliance A, B, C, D (6.40)"),
)


def model_config(spec: int | str) -> ModelConfig:
    """The model numbered ``spec`` (1–5, also as a string) or named ``spec``.

    Parameters
    ----------
    spec : int or str
        Number or name (case-insensitive).

    Returns
    -------
    ModelConfig
        The model.

    Raises
    ------
    ValueError
        No such model.
    """
    s = str(spec).strip().lower()
    for m in MODELS:
        if s in (str(m.number), m.name):
            return m
    names = ", ".join(f"{m.number}={m.name}" for m in MODELS)
    raise ValueError(f"unknown model {spec!r}; choose one of {names}")
