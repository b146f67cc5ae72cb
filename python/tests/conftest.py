"""Shared fixtures: the `hammer` CLI the package is compared with.

The CLI is the release binary of the workspace (`cargo build --release`),
found through $HAMMER_BIN, else $CARGO_TARGET_DIR/release/hammer, else
target/release/hammer at the repository's root. Missing, the tests fail: a
comparison with nothing proves nothing.
"""

import json
import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _hammer_path() -> Path:
    if os.environ.get("HAMMER_BIN"):
        return Path(os.environ["HAMMER_BIN"])
    target = Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    return target / "release" / "hammer"


class Hammer:
    def __init__(self, path: Path):
        self.path = path

    def run(self, *args, check=True) -> subprocess.CompletedProcess:
        done = subprocess.run([str(self.path), *map(str, args)], capture_output=True, text=True)
        if check and done.returncode != 0:
            raise AssertionError(f"hammer {' '.join(map(str, args))} failed: {done.stderr}")
        return done

    def error(self, *args) -> str:
        """The message of a refused command, as `error: MESSAGE` on stderr."""
        done = self.run(*args, check=False)
        assert done.returncode != 0, f"hammer {args} was not refused"
        at = done.stderr.find("error: ")
        assert at >= 0, done.stderr
        text = done.stderr[at + len("error: "):]
        return text[:-1] if text.endswith("\n") else text

    def jsonl(self, *args) -> list:
        return [json.loads(l) for l in self.run(*args).stdout.splitlines() if l.strip()]


@pytest.fixture(scope="session")
def hammer() -> Hammer:
    path = _hammer_path()
    assert path.is_file(), f"no hammer binary at {path}: build it with `cargo build --release` or set HAMMER_BIN"
    return Hammer(path)


@pytest.fixture(scope="session")
def simulated(hammer, tmp_path_factory) -> Path:
    """A trace `hammer simulate` wrote (with its sidecar), 0.3 s at 5 bar, with friction."""
    out = tmp_path_factory.mktemp("sim") / "trace.csv"
    hammer.run(
        "simulate", "--supply-bar", 5, "--duration", 0.3, "--seed", 11,
        "--effect", "coulomb_friction:k_n_per_bar=2.5", "--out", out,
    )
    return out
