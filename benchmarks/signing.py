"""What signed requests cost: ``python benchmarks/signing.py [--n N] [--e2e N] [--fuzz N]``.

Per request, for the key types a cell may use (ECDSA P-256 is what ``plugcell
certs`` issues): the size of a signed CreateProcess against an unsigned one, the time
to encode+sign it, to decode it, and to verify it — with the sender's certificate
already checked (the verifier keeps checked certificates by fingerprint) and the first
time (chain check included).  Then, unless ``--e2e 0``, the round trip of a NoData
process over a TLS link on loopback (a service without a journal, so that the
difference is the signature), unsigned with ``identity = "none"`` and signed with
``identity = "signed"``.  ``--fuzz N`` also mutates real signed envelopes N times (1–4
byte changes, insertions, deletions): each must be refused by the decoder or by the
verifier with a reason, and nothing may raise.  Speed is measured here, never
asserted in tests.
"""

from __future__ import annotations

import argparse
import asyncio
import datetime as dt
import json
import random
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ed25519, rsa
from cryptography.x509.oid import NameOID

from plugcell.framework import codec
from plugcell.framework.certificates import create_ca, issue_certificate
from plugcell.framework.messages import Command, Data, DataTypes, Process, Tag
from plugcell.framework.signing import RequestSigner, RequestVerifier
from plugcell.sim.ports import free_port


def _leaf(folder: Path, name: str, key: Any) -> x509.Certificate:
    ca_key = serialization.load_pem_private_key((folder / "ca.key").read_bytes(), None)
    ca = x509.load_pem_x509_certificate((folder / "ca.pem").read_bytes())
    now = dt.datetime.now(dt.UTC)
    return (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)]))
        .issuer_name(ca.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(minutes=5))
        .not_valid_after(now + dt.timedelta(days=1))
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .sign(ca_key, hashes.SHA256())  # type: ignore[arg-type]
    )


def _per_call_us(fn: Any, n: int) -> float:
    best = float("inf")
    for _ in range(3):  # best of three runs of n calls
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        best = min(best, (time.perf_counter() - t0) / n)
    return best * 1e6


def micro(folder: Path, n: int) -> list[dict[str, Any]]:
    signers = {"ECDSA P-256 (plugcell certs)": RequestSigner.load(folder / "ROBOT1.pem",
                                                                   folder / "ROBOT1.key")}
    for label, key in (("Ed25519", ed25519.Ed25519PrivateKey.generate()),
                       ("RSA 2048", rsa.generate_private_key(65537, 2048))):
        signers[label] = RequestSigner.from_objects(_leaf(folder, "ROBOT1", key), key)
    process = Process(command=Command(name="Move"), tag=Tag("ROBOT1", "TRACKER"),
                      identifier=1, data=Data(DataTypes.Double, (6,), b"\0" * 48))
    instance = f"{time.time_ns():016x}" + "ab" * 16
    plain = codec.encode("ROBOT1", instance, process)
    rows = []
    plain_encode = _per_call_us(lambda: codec.encode("ROBOT1", instance, process), n)
    plain_decode = _per_call_us(lambda: codec.decode(plain), n)
    for label, signer in signers.items():
        def sign(s: RequestSigner = signer) -> bytes:
            return s.encode("ROBOT1", instance, process, cell="bench", to="TRACKER")

        payload = sign()
        envelope = codec.decode(payload)
        verifier = RequestVerifier.load(folder / "ca.pem")

        def verify(v: RequestVerifier = verifier, e: codec.Envelope = envelope,
                   p: bytes = payload) -> None:
            v._nonces.clear()  # the same request again: not a replay for this measurement
            reason = v.verify(e, p, cell="bench", recipient="TRACKER", recipient_instance="")
            assert not reason, reason

        def cold(v: RequestVerifier = verifier) -> None:
            v._certs.clear()
            verify(v)

        rows.append({
            "key": label,
            "unsigned_bytes": len(plain),
            "signed_bytes": len(payload),
            "encode_unsigned_us": round(plain_encode, 1),
            "encode_sign_us": round(_per_call_us(sign, n), 1),
            "decode_unsigned_us": round(plain_decode, 1),
            "decode_signed_us": round(_per_call_us(lambda p=payload: codec.decode(p), n), 1),
            "verify_us": round(_per_call_us(verify, n), 1),
            "verify_first_us": round(_per_call_us(cold, max(n // 10, 10)), 1),
        })
    return rows


async def _round_trips(folder: Path, identity: str, n: int) -> list[float]:
    from plugcell.framework import Client, CommandTypes, GenericDevice, TransportConfig
    from plugcell.framework.declaration import Declaration
    from plugcell.framework.security import AccessPolicy

    class Echo:
        declaration = Declaration(kind="echo", commands=(
            Command(name="Ping", type=CommandTypes.NoData),))

        def bind(self, service: GenericDevice) -> None:
            """Ping answers with its code only."""

        async def dispatch(self, command: Command, option: str, data: Any) -> str:
            return command.success_code

    endpoint = f"tls/127.0.0.1:{free_port()}"
    tls = {"multicast": False, "tls_ca": str(folder / "ca.pem")}
    service_tp = TransportConfig(listen=(endpoint,), tls_cert=str(folder / "TRACKER.pem"),
                                 tls_key=str(folder / "TRACKER.key"), **tls)  # type: ignore[arg-type]
    client_tp = TransportConfig(listen=(), connect=(endpoint,),
                                tls_cert=str(folder / "ROBOT1.pem"),
                                tls_key=str(folder / "ROBOT1.key"),
                                sign_requests=identity == "signed", **tls)  # type: ignore[arg-type]
    cell = f"bench{time.time_ns() % 10**9}"
    service = GenericDevice(Echo(), "TRACKER", cell=cell, transport=service_tp, journal=False,
                            access=AccessPolicy(identity=identity))
    await service.start()
    try:
        async with Client("ROBOT1", cell=cell, transport=client_tp) as client:
            assert await client.wait_for("TRACKER", 10.0)
            times = []
            for i in range(n + 20):
                t0 = time.perf_counter()
                call = await client.create_process("TRACKER", "Ping")
                final = call.final or await call.result()
                assert final.state.value == "Completed", final.reason
                if i >= 20:  # warm-up
                    times.append((time.perf_counter() - t0) * 1e3)
            return times
    finally:
        await service.close()


def e2e(folder: Path, n: int) -> list[dict[str, Any]]:
    rows = []
    for identity in ("none", "signed"):
        t = sorted(asyncio.run(_round_trips(folder, identity, n)))
        rows.append({"identity": identity, "n": n,
                     "median_ms": round(statistics.median(t), 3),
                     "p95_ms": round(t[int(0.95 * (len(t) - 1))], 3),
                     "mean_ms": round(statistics.fmean(t), 3)})
    return rows


def fuzz(folder: Path, cases: int, seed: int = 20261122) -> dict[str, Any]:
    from plugcell.framework.messages import SubscribeRequest

    robot = RequestSigner.load(folder / "ROBOT1.pem", folder / "ROBOT1.key")
    process = Process(command=Command(name="Move"), tag=Tag("ROBOT1", "TRACKER"),
                      identifier=1, data=Data(DataTypes.Double, (6,), b"\0" * 48))
    now = time.time_ns()
    samples = [robot.encode("ROBOT1", "i1", process, cell="bench", to="TRACKER", time_ns=now),
               robot.encode("ROBOT1", "i1", SubscribeRequest(partner="X"), cell="bench",
                            to="TRACKER", time_ns=now)]
    rng = random.Random(seed)
    counts = {"cases": cases, "seed": seed, "decoder": 0, "verifier": 0, "unchanged": 0}
    t0 = time.perf_counter()
    for _ in range(cases):
        b = bytearray(rng.choice(samples))
        for _ in range(rng.choice((1, 1, 1, 2, 4))):
            op, i = rng.random(), rng.randrange(len(b))
            if op < 0.7:
                b[i] = rng.randrange(256)
            elif op < 0.85:
                del b[i]
            else:
                b.insert(i, rng.randrange(256))
        payload = bytes(b)
        if payload in samples:
            counts["unchanged"] += 1
            continue
        try:
            envelope = codec.decode(payload)
        except codec.WireError:
            counts["decoder"] += 1
            continue
        verifier = RequestVerifier.load(folder / "ca.pem")
        reason = verifier.verify(envelope, payload, cell="bench", recipient="TRACKER",
                                 recipient_instance="")
        if not reason.startswith("access denied: ") or "cannot verify" in reason:
            raise AssertionError(f"tampered envelope {payload.hex()}: {reason!r}")
        counts["verifier"] += 1
    counts["seconds"] = round(time.perf_counter() - t0, 1)
    return counts


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=2000, help="calls per micro measurement")
    ap.add_argument("--e2e", type=int, default=500, help="round trips per identity (0: skip)")
    ap.add_argument("--fuzz", type=int, default=0, help="tampered signed envelopes to check")
    ap.add_argument("--json", action="store_true", help="print JSON instead of tables")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        create_ca(folder, "bench")
        for name in ("ROBOT1", "TRACKER"):
            issue_certificate(folder, name)
        out: dict[str, Any] = {"micro": micro(folder, args.n)}
        if args.e2e > 0:
            out["round_trip"] = e2e(folder, args.e2e)
        if args.fuzz > 0:
            out["fuzz"] = fuzz(folder, args.fuzz)
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    print("Signed CreateProcess (Move, 6 doubles), per request, best of 3 × "
          f"{args.n} calls")
    print(f"{'key':<30} {'bytes':>11} {'encode µs':>14} {'decode µs':>11} "
          f"{'verify µs':>10} {'1st verify µs':>14}")
    for r in out["micro"]:
        print(f"{r['key']:<30} {r['unsigned_bytes']:>4} → {r['signed_bytes']:<4} "
              f"{r['encode_unsigned_us']:>5} → {r['encode_sign_us']:<6} "
              f"{r['decode_unsigned_us']:>4} → {r['decode_signed_us']:<4} "
              f"{r['verify_us']:>10} {r['verify_first_us']:>14}")
    for r in out.get("round_trip", []):
        if r is out["round_trip"][0]:
            print(f"\nRound trip of a NoData process, TLS on loopback, no journal, "
                  f"{r['n']} sequential")
            print(f"{'identity':<10} {'median ms':>10} {'p95 ms':>8} {'mean ms':>8}")
        print(f"{r['identity']:<10} {r['median_ms']:>10} {r['p95_ms']:>8} {r['mean_ms']:>8}")
    if "fuzz" in out:
        f = out["fuzz"]
        print(f"\nTampered signed envelopes: {f['cases']} (seed {f['seed']}), refused by the "
              f"decoder {f['decoder']}, by the verifier {f['verifier']}, unchanged "
              f"{f['unchanged']}, accepted 0, crashes 0 ({f['seconds']} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
