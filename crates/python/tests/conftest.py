"""Fixtures of the Python package's tests: the mdtf command they compare
with ($MDTF_BIN, else the workspace's target/debug/mdtf) and phantoms it
writes."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="session")
def mdtf_bin() -> Path:
    path = Path(os.environ.get("MDTF_BIN", REPO / "target" / "debug" / "mdtf"))
    if not path.is_file():
        pytest.fail(f"the mdtf command is not at {path}: build it (cargo build -p mdtf-cli) or set MDTF_BIN")
    return path


def cli(mdtf_bin: Path, *args: str | os.PathLike[str]) -> subprocess.CompletedProcess[str]:
    """Runs the mdtf command quietly; fails the test with its stderr when it fails."""
    r = subprocess.run([str(mdtf_bin), *map(str, args), "-q"], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.fail(f"mdtf {' '.join(map(str, args))} failed ({r.returncode}): {r.stderr}")
    return r


@pytest.fixture(scope="session")
def sphere(mdtf_bin: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A noisy erf sphere, 40 x 44 x 48 voxels of 0.8 x 1.0 x 1.2 mm (anisotropic, not a cube)."""
    path = tmp_path_factory.mktemp("phantom") / "sphere.nii"
    cli(mdtf_bin, "synth", "erf-sphere", "--size", "40,44,48", "--spacing", "0.8,1.0,1.2", "--noise", "2", "-o", path)
    return path


@pytest.fixture(scope="session")
def pipelines() -> Path:
    return REPO / "pipelines"
