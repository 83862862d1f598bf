"""The journal's write-ahead log: an append-only file in front of its SQLite database.

Keeping the journal's rule (a process is recorded before it is acknowledged, an update
before it is published) with one SQLite transaction per turn of the event loop cost
≈ 30 µs of every 4-byte round trip's one-way latency, about a third of raw Zenoh's own
(``benchmarks/durability_floor.py``).  Appending the same rows to a file with one
``write`` keeps the rule at the same strength — like SQLite's WAL with
``synchronous=NORMAL``, what the kernel has survives the death of the process; with
``durable`` each append is also ``fdatasync``-ed, surviving a power cut — and costs
≈ 2 µs.  The journal moves the rows into SQLite in the background
(:class:`~plugcell.framework.journal.Journal`); readers read SQLite and the part of the
log not moved yet.

File layout (little-endian)::

    header   8 s   magic  b"PCJLOG01"
             u64   generation (random; a new one each time the file restarts empty)
    record   u32   length n of the body
             u32   CRC-32 of the body
             n B   body: MessagePack array of [kind, row] pairs, kind 0 process,
                   1 update, 2 rejection; a row is the array of its table's columns

A record is whole or absent: a reader stops at the first record that is cut short or
fails its checksum (the tail of a write that a crash interrupted; nothing of it was
acknowledged, since the write had not returned).
"""

from __future__ import annotations

import contextlib
import os
import secrets
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec

MAGIC = b"PCJLOG01"
HEADER = struct.Struct("<8sQ")
RECORD = struct.Struct("<II")

PROCESS, UPDATE, REJECTION = 0, 1, 2
"""Row kinds: the table a row belongs to."""

Row = tuple[int, list[Any]]
"""``(kind, columns)``."""

_decoder = msgspec.msgpack.Decoder(list[tuple[int, list[Any]]])


def log_path(database: Path) -> Path:
    """The log of the journal ``database``: ``<name>.sqlite.log`` beside it."""
    return database.with_name(database.name + ".log")


def encode(rows: list[Row], encoder: msgspec.msgpack.Encoder) -> bytes:
    """One record holding ``rows``."""
    body = encoder.encode(rows)
    return RECORD.pack(len(body), zlib.crc32(body)) + body


@dataclass(frozen=True)
class Contents:
    """What :func:`read_log` found from an offset on."""

    generation: int
    rows: list[Row]
    end: int
    """Offset after the last whole record read (where a torn tail, if any, begins)."""
    records: list[tuple[int, list[Row]]]
    """``(end offset, rows)`` of each record, in order."""


def read_log(path: Path, start: int | None = None) -> Contents | None:
    """The whole records of the log at ``path`` from offset ``start`` (a record boundary
    of this generation, e.g. a mark; the first record when None or before it); None when
    there is no file or not yet a whole header.  Only the part from ``start`` is read."""
    try:
        with open(path, "rb") as f:
            header = f.read(HEADER.size)
            if len(header) < HEADER.size:
                return None
            magic, generation = HEADER.unpack(header)
            if magic != MAGIC:
                raise ValueError(f"{path} is not a plugcell journal log")
            first = HEADER.size if start is None or start < HEADER.size else start
            f.seek(first)
            data = f.read()
    except FileNotFoundError:
        return None
    pos = 0
    rows: list[Row] = []
    records: list[tuple[int, list[Row]]] = []
    while pos + RECORD.size <= len(data):
        length, crc = RECORD.unpack_from(data, pos)
        body = data[pos + RECORD.size : pos + RECORD.size + length]
        if len(body) < length or zlib.crc32(body) != crc:
            break
        try:
            batch = _decoder.decode(body)
        except msgspec.DecodeError:
            break
        pos += RECORD.size + length
        rows.extend(batch)
        records.append((first + pos, batch))
    return Contents(generation, rows, first + pos, records)


class LogWriter:
    """The appending end of a journal's log (one per open journal; not thread-safe:
    the journal serialises its calls)."""

    def __init__(self, path: Path, *, durable: bool) -> None:
        self.path = path
        self.durable = durable
        self._fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_APPEND | os.O_CLOEXEC, 0o644)
        self.generation = 0
        self.size = os.fstat(self._fd).st_size

    def restart(self) -> int:
        """Empty the file and start a new generation (after everything in it was moved
        into the database); returns the new generation.  Should writing the header fail
        (a full disk), the file is left empty and the next :meth:`append` starts it."""
        os.ftruncate(self._fd, 0)
        self.size = 0
        generation = secrets.randbits(63) + 1
        self._write(HEADER.pack(MAGIC, generation))
        self.generation = generation
        self.size = HEADER.size
        return generation

    def append(self, record: bytes) -> int:
        """Append one record; returns the offset after it.  Durable when it returns; if
        it raises (a full disk), the file is as before (no torn record in the middle)."""
        if self.size < HEADER.size:  # a restart that could not write its header
            self.restart()
        try:
            self._write(record)
        except BaseException:
            with contextlib.suppress(OSError):
                os.ftruncate(self._fd, self.size)
            raise
        self.size += len(record)
        return self.size

    def _write(self, data: bytes) -> None:
        written = os.write(self._fd, data)
        while written < len(data):  # a regular file takes it whole unless the disk is full
            written += os.write(self._fd, data[written:])
        if self.durable:
            os.fdatasync(self._fd)

    def close(self, *, delete: bool) -> None:
        os.close(self._fd)
        if delete:
            self.path.unlink(missing_ok=True)
