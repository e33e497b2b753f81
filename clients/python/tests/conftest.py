"""The real service for the tests: the contact-sim binary (``$CONTACT_SIM_BIN``, else the
repository's target/release, else target/debug) serving a throwaway data directory on an
ephemeral loopback port, one server for the whole session."""

from __future__ import annotations

import contextlib
import os
import re
import subprocess
import time
from pathlib import Path
from typing import Iterator

import pytest

from contact_sim import Client

REPO = Path(__file__).resolve().parents[3]
MESHES = REPO / "crates" / "contact-core" / "preset-meshes"


def binary() -> Path:
    env = os.environ.get("CONTACT_SIM_BIN")
    if env:
        return Path(env)
    for profile in ("release", "debug"):
        candidate = REPO / "target" / profile / "contact-sim"
        if candidate.exists():
            return candidate
    raise RuntimeError(
        "no contact-sim binary: set CONTACT_SIM_BIN or build it (cargo build --bin contact-sim)"
    )


@contextlib.contextmanager
def serve(data: Path, *extra: str) -> Iterator[str]:
    """A server on `data` (its log next to it) for as long as the block runs: its URL."""
    log_path = data.parent / f"{data.name}.log"
    with open(log_path, "wb") as log:
        proc = subprocess.Popen(
            [str(binary()), "serve", "--addr", "127.0.0.1:0", "--data-dir", str(data), *extra],
            stdout=log,
            stderr=subprocess.STDOUT,
            env={**os.environ, "RUST_LOG": "info"},
        )
    try:
        url = None
        deadline = time.monotonic() + 30
        while url is None and time.monotonic() < deadline and proc.poll() is None:
            m = re.search(r"listening on (http://\S+)", log_path.read_text(errors="replace"))
            if m:
                url = m.group(1)
            else:
                time.sleep(0.05)
        if url is None:
            raise RuntimeError(f"contact-sim serve did not start:\n{log_path.read_text()}")
        yield url
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    assert "panicked" not in log_path.read_text(errors="replace"), log_path.read_text()


@pytest.fixture(scope="session")
def server_url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    with serve(tmp_path_factory.mktemp("data"), "--workers", "2", "--submit-rate", "0") as url:
        yield url


@pytest.fixture
def client(server_url: str) -> Iterator[Client]:
    with Client(server_url) as c:
        yield c
