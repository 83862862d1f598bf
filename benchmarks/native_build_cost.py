"""What a native hot path would add to a fresh machine's setup: build a minimal PyO3
extension against the zenoh crate and time it.

    .venv/bin/python benchmarks/native_build_cost.py [--zenoh 1.10.0 | --without-zenoh
        | --probe] [--keep DIR]

Issue 20 allows the request/acknowledge/update path in native code (a Rust extension
built against the zenoh crate) on condition that ``make demo`` / ``make test`` on a fresh
machine still set up in a time a newcomer accepts.  This measures that condition's
lower bound: a crate with PyO3 and zenoh (TCP, UDP, shared memory — the transports
plugcell uses) and one function that opens and closes a session, built with
``cargo build --release`` from an empty target directory (crates.io must be reachable,
or its crates already in cargo's cache).  A real hot path would add its own code on top.
Not part of ``make bench``: it downloads crates and keeps both cores busy for minutes.

``--without-zenoh`` builds the other way to go native instead: the per-message work in
Rust (PyO3 and a MessagePack codec, ``rmp-serde``), called from the Zenoh callbacks of
eclipse-zenoh's own Python session — one function that decodes a map and encodes it
again.  docs/results/framework-performance.md ("In one picture") shows why that suffices:
Python glue that only puts bytes prepared elsewhere stays within the target.  ``--probe``
builds that measuring device itself, ``benchmarks/native_probe``, from its sources.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PACKAGE = """[package]
name = "plugcell_native_probe"
version = "0.1.0"
edition = "2021"

[lib]
crate-type = ["cdylib"]

[dependencies]
pyo3 = { version = "0.25", features = ["extension-module"] }
"""


def cargo_toml(zenoh: str | None) -> str:
    """The probe's Cargo.toml: PyO3 with the zenoh crate ``zenoh`` (exact version; the
    transports plugcell uses), or with a MessagePack codec instead (None)."""
    if zenoh is None:
        return PACKAGE + 'serde = { version = "1", features = ["derive"] }\nrmp-serde = "1"\n'
    return PACKAGE + (f'zenoh = {{ version = "={zenoh}", default-features = false, features = [\n'
                      '    "transport_tcp", "transport_udp", "shared-memory",\n] }\n')


LIB_RS = """use pyo3::prelude::*;
use zenoh::Wait;

/// Open a Zenoh session and close it; its id.
#[pyfunction]
fn open_and_close() -> PyResult<String> {
    let err = |e: zenoh::Error| pyo3::exceptions::PyRuntimeError::new_err(e.to_string());
    let session = zenoh::open(zenoh::Config::default()).wait().map_err(err)?;
    let zid = session.zid().to_string();
    session.close().wait().map_err(err)?;
    Ok(zid)
}

#[pymodule]
fn plugcell_native_probe(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(open_and_close, m)?)?;
    Ok(())
}
"""


LIB_RS_WITHOUT_ZENOH = """use pyo3::prelude::*;
use std::collections::BTreeMap;

/// Decode a MessagePack map of strings and encode it again (what the codec costs to build).
#[pyfunction]
fn round_trip(payload: &[u8]) -> PyResult<Vec<u8>> {
    let err = |e: String| pyo3::exceptions::PyValueError::new_err(e);
    let map: BTreeMap<String, String> =
        rmp_serde::from_slice(payload).map_err(|e| err(e.to_string()))?;
    rmp_serde::to_vec_named(&map).map_err(|e| err(e.to_string()))
}

#[pymodule]
fn plugcell_native_probe(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(round_trip, m)?)?;
    Ok(())
}
"""


def _size(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    flavour = parser.add_mutually_exclusive_group()
    flavour.add_argument("--zenoh", default="1.10.0", help="zenoh crate version (exact)")
    flavour.add_argument("--without-zenoh", action="store_true",
                         help="PyO3 and a MessagePack codec only (module docstring)")
    flavour.add_argument("--probe", action="store_true",
                         help="benchmarks/native_probe, durability_floor.py's measuring device")
    parser.add_argument("--keep", type=Path, help="build here and keep it (default: a "
                        "temporary folder, removed)")
    args = parser.parse_args(argv)
    cargo = shutil.which("cargo")
    if cargo is None:
        print("cargo not found: no Rust toolchain on this machine (skipped)")
        return 0
    root = args.keep or Path(tempfile.mkdtemp(prefix="plugcell-native-"))
    (root / "src").mkdir(parents=True, exist_ok=True)
    if args.probe:
        what = "benchmarks/native_probe"
        probe = Path(__file__).with_name("native_probe")
        for name in ("Cargo.toml", "Cargo.lock", "src/lib.rs"):
            shutil.copy(probe / name, root / name)
    elif args.without_zenoh:
        what = "PyO3 + rmp-serde"
        (root / "Cargo.toml").write_text(cargo_toml(None), encoding="utf-8")
        (root / "src" / "lib.rs").write_text(LIB_RS_WITHOUT_ZENOH, encoding="utf-8")
    else:
        what = f"PyO3 + zenoh {args.zenoh}"
        (root / "Cargo.toml").write_text(cargo_toml(args.zenoh), encoding="utf-8")
        (root / "src" / "lib.rs").write_text(LIB_RS, encoding="utf-8")
    print(f"building a {what} extension in {root} "
          f"({os.cpu_count()} cores, {platform.machine()}, load {os.getloadavg()[0]:.1f})",
          flush=True)
    started = time.perf_counter()
    cpu0 = os.times()
    done = subprocess.run([cargo, "build", "--release"], cwd=root, capture_output=True,
                          text=True)
    wall = time.perf_counter() - started
    cpu1 = os.times()
    if done.returncode != 0:
        print(done.stderr[-3000:])
        return 1
    locked = re.search(r"Locking (\d+) packages", done.stderr)
    lock = root / "Cargo.lock"  # a crate that brings its lock file locks nothing anew
    crates = locked.group(1) if locked else (
        str(lock.read_text().count("[[package]]") - 1) if lock.is_file() else "?")
    library = next((root / "target" / "release").glob("*.so"), None)
    cpu = (cpu1.children_user - cpu0.children_user) + (cpu1.children_system
                                                       - cpu0.children_system)
    print(f"crates locked:            {crates}")
    print(f"cargo build --release:    {wall / 60:.1f} min wall ({wall:.0f} s), "
          f"{cpu / 60:.1f} min CPU ({cpu:.0f} s)")
    print(f"target directory:         {_size(root / 'target') / 1e6:.0f} MB")
    if library is not None:
        print(f"extension module:         {library.stat().st_size / 1e6:.1f} MB")
    if args.keep is None:
        shutil.rmtree(root, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
