"""Writing what the user copies to a controller, from templates shipped as package data."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

__all__ = ["fill_template", "write_files"]


def fill_template(package: str, name: str, **values: object) -> str:
    """The template ``controller/name`` of ``package`` with each ``{{key}}`` replaced.

    Parameters
    ----------
    package : str
        The package that ships the template in its ``controller/`` folder.
    name : str
        The template's file name.
    **values
        ``key=value`` for each ``{{key}}`` (the controllers' own syntax stays as it is).

    Returns
    -------
    str
        The text.

    Raises
    ------
    KeyError
        A placeholder left unfilled (a bug of the caller).
    """
    text = resources.files(package).joinpath("controller", name).read_text(encoding="utf-8")
    for key, value in values.items():
        text = text.replace("{{" + key + "}}", str(value))
    if "{{" in text:
        raise KeyError(f"{name}: a placeholder is not filled: "
                       f"{text[text.index('{{'):text.index('{{') + 30]!r}")
    return text


def write_files(out: Path, files: dict[str, str]) -> list[Path]:
    """Write ``files`` (name → text) into the folder ``out`` (made if missing), CRLF
    line ends as the controllers' Windows-side tools expect.

    Parameters
    ----------
    out : Path
        The folder.
    files : dict of str to str
        File name → text.

    Returns
    -------
    list of Path
        The files written.
    """
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, text in files.items():
        path = out / name
        path.write_bytes(text.replace("\n", "\r\n").encode("utf-8"))
        written.append(path)
    return written
