"""What a native hot path would add to a fresh machine's setup: build a minimal PyO3
extension against the zenoh crate and time it.

    .venv/bin/python benchmarks/native_build_cost.py [--zenoh 1.10.0] [--keep DIR]

Issue 20 allows the request/acknowledge/update path in native code (a Rust extension
built against the zenoh crate) on condition that ``make demo`` / ``make test`` on a fresh
machine still set up in a time a newcomer accepts.  This measures that condition's
lower bound: a crate with PyO3 and zenoh (TCP, UDP, shared memory — the transports
plugcell uses) and one function that opens and closes a session, built with
``cargo build --release`` from an empty target directory (crates.io must be reachable,
or its crates already in cargo's cache).  A real hot path would add its own code on top.
Not part of ``make bench``: it downloads crates and keeps both cores busy for minutes.
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

CARGO_TOML = """[package]
name = "plugcell_native_probe"
version = "0.1.0"
edition = "2021"

[lib]
crate-type = ["cdylib"]

[dependencies]
pyo3 = {{ version = "0.25", features = ["extension-module"] }}
zenoh = {{ version = "={zenoh}", default-features = false, features = [
    "transport_tcp", "transport_udp", "shared-memory",
] }}
"""

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


def _size(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--zenoh", default="1.10.0", help="zenoh crate version (exact)")
    parser.add_argument("--keep", type=Path, help="build here and keep it (default: a "
                        "temporary folder, removed)")
    args = parser.parse_args(argv)
    cargo = shutil.which("cargo")
    if cargo is None:
        print("cargo not found: no Rust toolchain on this machine (skipped)")
        return 0
    root = args.keep or Path(tempfile.mkdtemp(prefix="plugcell-native-"))
    (root / "src").mkdir(parents=True, exist_ok=True)
    (root / "Cargo.toml").write_text(CARGO_TOML.format(zenoh=args.zenoh), encoding="utf-8")
    (root / "src" / "lib.rs").write_text(LIB_RS, encoding="utf-8")
    print(f"building a PyO3 + zenoh {args.zenoh} extension in {root} "
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
    crates = re.search(r"Locking (\d+) packages", done.stderr)
    library = next((root / "target" / "release").glob("*.so"), None)
    cpu = (cpu1.children_user - cpu0.children_user) + (cpu1.children_system
                                                       - cpu0.children_system)
    print(f"crates locked:            {crates.group(1) if crates else '?'}")
    print(f"cargo build --release:    {wall / 60:.1f} min wall, {cpu / 60:.1f} min CPU")
    print(f"target directory:         {_size(root / 'target') / 1e6:.0f} MB")
    if library is not None:
        print(f"extension module:         {library.stat().st_size / 1e6:.1f} MB")
    if args.keep is None:
        shutil.rmtree(root, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
