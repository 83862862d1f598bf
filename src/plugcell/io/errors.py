"""The errors of the file formats that more than one reader raises."""

from __future__ import annotations

from plugcell.kinematics.errors import DescriptionError

__all__ = ["RobotNotFoundError"]


class RobotNotFoundError(DescriptionError, LookupError):
    """No shipped robot of that name, or no such file.

    Parameters
    ----------
    message : str
        The whole message (the error's location is empty).
    """

    def __init__(self, message: str) -> None:
        super().__init__("", message)
