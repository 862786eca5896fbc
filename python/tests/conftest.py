"""Shared fixtures: the `forgemon` binary the package is compared with, and recordings
made by it (`forgemon demo --fast`), once per session."""

import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "config"


@pytest.fixture(scope="session")
def forgemon_bin():
    """The CLI: `FORGEMON_BIN`, else the release build of this checkout."""
    path = Path(os.environ.get("FORGEMON_BIN", ROOT / "target" / "release" / "forgemon"))
    if not path.exists():
        pytest.fail(f"{path}: no forgemon binary; run `cargo build --release` or set FORGEMON_BIN")
    return str(path)


def cli(bin_, *args, **kw):
    """Run the CLI; its completed process (failing the test on a non-zero exit)."""
    return subprocess.run([bin_, *map(str, args)], capture_output=True, text=kw.pop("text", True), check=kw.pop("check", True), **kw)


@pytest.fixture(scope="session")
def fleet_dir(tmp_path_factory, forgemon_bin):
    """Two machines' rotated runs: `forgemon demo --fast --billets 2 --rotate-mib 5`, four
    files each, eight in all."""
    root = tmp_path_factory.mktemp("fleet")
    for machine in ("hammer-a", "hammer-b"):
        cli(forgemon_bin, "demo", "--fast", "--billets", "2", "--lot", f"L-{machine}", "--die", "D1", "--rotate-mib", "5", "--dir", root / machine)
        (root / machine / "history.sqlite").unlink()
    return root
