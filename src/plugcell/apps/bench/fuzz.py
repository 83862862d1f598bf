"""Fuzzing of the wire decoder: random bytes and mutations of valid messages.

Only :class:`~plugcell.framework.codec.WireError` may come out of the decoder,
and a decoded buffer is checked with :func:`check_data`, which may only raise
:class:`DataError`.  Used by the tests (a few thousand cases) and by
``benchmarks/fuzz_wire.py`` (≥ 100 000 cases).
"""

from __future__ import annotations

import random

import numpy as np

from plugcell.framework import codec
from plugcell.framework.data import DataError, check_data, from_data, to_data
from plugcell.framework.messages import (
    Command,
    DataTypes,
    Device,
    GenericDeviceState,
    GetRequest,
    Process,
    ProcessStates,
    ProcessUpdateNotification,
    Tag,
)


def seed_messages() -> list[bytes]:
    """Valid messages of every shape worth mutating."""
    image = to_data(np.arange(12, dtype=np.int32).reshape(3, 4), DataTypes.Integer, (3, 4))
    return [
        codec.encode(
            "ROBOT",
            "abc",
            Process(
                command=Command(name="Set"), tag=Tag("ROBOT", "DEV"), identifier=99, data=image
            ),
        ),
        codec.encode("A", "i", GetRequest()),
        codec.encode(
            "A",
            "i",
            ProcessUpdateNotification(
                tag=Tag("A", "B"),
                identifier=3,
                state=ProcessStates.Running,
                data=to_data([1.0, 2.0], DataTypes.Double, (2,)),
            ),
        ),
        codec.encode(
            "A",
            "i",
            ProcessUpdateNotification(
                tag=Tag("A", "B"),
                identifier=4,
                state=ProcessStates.Completed,
                data=to_data(["a", "bc"], DataTypes.String, (2,)),
            ),
        ),
        codec.encode(
            "A",
            "i",
            GenericDeviceState(
                device_info=Device(name="CAM", commands=(Command(name="SnapShot"),))
            ),
        ),
    ]


def mutate(rng: random.Random, payload: bytes) -> bytes:
    """Flip, insert or delete a few bytes."""
    buf = bytearray(payload)
    for _ in range(rng.randint(1, 4)):
        op = rng.randint(0, 2)
        pos = rng.randrange(len(buf)) if buf else 0
        if op == 0 and buf:
            buf[pos] = rng.getrandbits(8)
        elif op == 1:
            buf[pos:pos] = bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 8)))
        elif buf:
            del buf[pos : pos + rng.randint(1, 8)]
    return bytes(buf)


def fuzz_decoder(cases: int, seed: int = 1234) -> dict[str, int]:
    """Run ``cases`` fuzz cases; return counts of decoded / rejected / lying-data cases.

    Any exception other than WireError/DataError propagates (the caller fails).
    """
    rng = random.Random(seed)
    seeds = seed_messages()
    counts = {"decoded": 0, "rejected": 0, "lying_data": 0}
    for i in range(cases):
        if i % 4 == 0:
            payload = bytes(rng.getrandbits(8) for _ in range(rng.randint(0, 64)))
        else:
            payload = mutate(rng, rng.choice(seeds))
        try:
            envelope = codec.decode(payload)
        except codec.WireError:
            counts["rejected"] += 1
            continue
        counts["decoded"] += 1
        data = getattr(envelope.body, "data", None)
        if data is not None:
            try:
                check_data(data, data.type, data.size)
            except DataError:
                counts["lying_data"] += 1
            else:
                from_data(data)
    return counts
