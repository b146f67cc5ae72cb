"""docs/python.md runs as written: its shell blocks with bash, its Python
blocks in order in one namespace, all in a scratch directory, with the
`hammer` CLI on the PATH. The page's asserts are its claims."""

import os
import re
import subprocess
from pathlib import Path

from conftest import ROOT

PAGE = ROOT / "docs" / "python.md"


def blocks(text: str):
    """(language, code) of every fenced block, in order."""
    return [(m.group(1), m.group(2)) for m in re.finditer(r"^```(\w*)\n(.*?)^```", text, re.S | re.M)]


def test_the_page_has_the_blocks_it_needs():
    langs = [lang for lang, _ in blocks(PAGE.read_text())]
    assert langs.count("python") >= 5
    assert all(lang in ("python", "sh") for lang in langs), langs


def test_every_block_of_docs_python_md_runs(hammer, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    env = dict(os.environ, PATH=f"{hammer.path.parent}{os.pathsep}{os.environ['PATH']}")
    namespace = {"__name__": "__docs__"}
    ran = 0
    for i, (lang, code) in enumerate(blocks(PAGE.read_text())):
        if lang == "sh":
            if "pip install" in code:
                continue  # the install itself: `cargo xtask ci` runs it (a fresh venv, `pip install ./python`)
            done = subprocess.run(["bash", "-euo", "pipefail", "-c", code], env=env, capture_output=True, text=True)
            assert done.returncode == 0, f"block {i} (sh) failed:\n{code}\n{done.stderr}"
        else:
            exec(compile(code, f"docs/python.md block {i}", "exec"), namespace)
        ran += 1
    assert ran >= 6
    # The figure the page draws was written.
    assert (tmp_path / "friction-vs-supply.png").stat().st_size > 10_000
