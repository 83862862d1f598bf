"""Reading one of plugcell's text files (measurements, plans, nests, paths, moves): UTF-8,
and an error of the file format's own class that names the file and the cause."""

from __future__ import annotations

from pathlib import Path


def read_text(path: str | Path, error: type[Exception], name: str | None = None) -> str:
    """The text of the UTF-8 file ``path``.

    Parameters
    ----------
    path : str or Path
        The file.
    error : type of Exception
        The file format's error class, raised with one message.
    name : str, optional
        How the message names the file (default: ``path``).

    Returns
    -------
    str
        Its text.

    Raises
    ------
    error
        ``<name>: cannot read: no such file``, ``…: not a UTF-8 text file (<why>)`` or
        ``…: <the OS's reason>``.
    """
    p = Path(path)
    label = str(p) if name is None else name
    try:
        return p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise error(f"{label}: cannot read: no such file") from None
    except UnicodeDecodeError as exc:
        raise error(f"{label}: cannot read: not a UTF-8 text file ({exc.reason})") from None
    except OSError as exc:
        raise error(f"{label}: cannot read: {exc.strerror or exc}") from None
