"""Exceptions of :mod:`plugcell.kinematics`.

Every error the kinematics raises on bad input or an impossible request derives
from :class:`KinematicsError`, so a caller can catch the whole family at once.
"""

from __future__ import annotations


class KinematicsError(Exception):
    """Base class of every kinematics error."""


class DescriptionError(KinematicsError, ValueError):
    """A robot description is malformed.

    ``location`` is a path-like pointer into the description (``links[3].alpha``),
    ``reason`` says what is wrong; ``str(err)`` is ``"location: reason"``.  File
    loaders prepend the file name to ``location``.
    """

    def __init__(self, location: str, reason: str) -> None:
        self.location = location
        self.reason = reason
        super().__init__(f"{location}: {reason}" if location else reason)

    def with_prefix(self, prefix: str) -> DescriptionError:
        """The same error with ``prefix`` (e.g. a file name) before the location.

        Parameters
        ----------
        prefix : str
            Text to put before the location, ``"prefix: location"``.

        Returns
        -------
        DescriptionError
            A new error (this one is unchanged).
        """
        loc = f"{prefix}: {self.location}" if self.location else prefix
        return DescriptionError(loc, self.reason)


class LoopClosureError(KinematicsError, ValueError):
    """A closed loop cannot be assembled, or collapses, for the given joint values.

    ``index`` is the batch index of the first offending configuration (``None``
    for a single configuration).
    """

    def __init__(self, message: str, index: tuple[int, ...] | None = None) -> None:
        self.index = index
        super().__init__(message)


class UnreachableError(KinematicsError):
    """Inverse kinematics found no joint solution for a pose.

    ``reason`` is ``"out of reach"`` or ``"no convergence"``; ``index`` the batch
    index of the target (``None`` for a single target).
    """

    def __init__(
        self,
        message: str,
        *,
        reason: str = "no convergence",
        index: tuple[int, ...] | None = None,
    ) -> None:
        self.reason = reason
        self.index = index
        super().__init__(message)


class JointLimitError(KinematicsError):
    """A joint solution exists but violates a joint limit (or a coupled limit).

    ``joint`` names the joint (or ``"2 - 2'"`` for a coupled difference limit),
    ``value`` is its value and ``limit`` the violated ``(lower, upper)`` interval,
    both in radians.
    """

    def __init__(
        self,
        message: str,
        *,
        joint: str,
        value: float,
        limit: tuple[float, float],
        index: tuple[int, ...] | None = None,
    ) -> None:
        self.joint = joint
        self.value = value
        self.limit = limit
        self.index = index
        super().__init__(message)
