"""Fixtures of the ndfit package tests: the CLI binary they compare against, synthetic scans the CLI writes,
and the shared real scans (skipped with a note when ../shared is absent, a failure under
NDFIT_REQUIRE_SHARED=1)."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SHARED_SCANS = REPO.parent / "shared" / "data" / "scans"


def _require_shared() -> bool:
    return os.environ.get("NDFIT_REQUIRE_SHARED", "0") not in ("", "0")


@pytest.fixture(scope="session")
def ndfit_bin() -> str:
    """The `ndfit` binary: $NDFIT, else target/release/ndfit (built by `cargo build --release`)."""
    b = os.environ.get("NDFIT") or str(REPO / "target" / "release" / "ndfit")
    if not os.path.isabs(b):
        b = str(REPO / b)
    if not os.access(b, os.X_OK):
        pytest.fail(f"the ndfit binary {b} is missing: run `cargo build --release` or set NDFIT")
    return b


def run_cli(ndfit_bin: str, *args: str, check: bool = True) -> subprocess.CompletedProcess:
    r = subprocess.run([ndfit_bin, *map(str, args)], capture_output=True, text=True)
    if check and r.returncode != 0:
        raise AssertionError(f"ndfit {' '.join(map(str, args))} failed ({r.returncode}): {r.stderr}")
    return r


@pytest.fixture(scope="session")
def synth_dir(tmp_path_factory, ndfit_bin) -> Path:
    """A folder of small synthetic scans written by `ndfit synth` (X3P with a known truth)."""
    d = tmp_path_factory.mktemp("synth")
    specs = {
        "ell_aniso.x3p": ["--surface", "ellipsoid", "--nx", "192", "--ny", "160", "--alpha-x", "0.35", "--alpha-y", "0.2", "--theta-z", "0.4"],
        "ell_skew.x3p": ["--surface", "ellipsoid", "--nx", "160", "--ny", "160", "--alpha-x", "0.3", "--theta-x", "0.15"],
        "gauss.x3p": ["--surface", "gaussian", "--nx", "256", "--ny", "256", "--sigma-x", "0.25", "--sigma-y", "0.15", "--theta-z", "0.3"],
        "gauss_holes.x3p": ["--surface", "gaussian", "--nx", "200", "--ny", "220", "--dx", "5e-7", "--dy", "7e-7", "--holes", "0.05", "--seed", "3"],
    }
    for name, args in specs.items():
        run_cli(ndfit_bin, "synth", d / name, *args)
    return d


@pytest.fixture(scope="session")
def shared_scans() -> Path:
    """The shared real scans (../shared/data/scans)."""
    if not (SHARED_SCANS / "peer_readings.json").is_file():
        if _require_shared():
            pytest.fail(f"{SHARED_SCANS} is absent and NDFIT_REQUIRE_SHARED is set")
        pytest.skip(f"SKIP: {SHARED_SCANS} is absent (real-scan checks need ../shared beside the repository)")
    return SHARED_SCANS


def real_scan_files(folder: Path) -> list:
    """The shared scan files (everything but the notes and the peer readings)."""
    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() not in (".json", ".md"))
