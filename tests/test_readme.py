"""The README a new user reads first: under 300 lines, every file it links to exists, and CI
runs exactly its test command."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def test_the_readme_is_under_300_lines():
    assert len(README.splitlines()) < 300


def test_every_file_the_readme_and_docs_link_to_exists():
    missing = []
    for page in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", page.read_text()):
            if "://" not in target and not (page.parent / target).exists():
                missing.append(f"{page.relative_to(ROOT)} -> {target}")
    assert missing == []


def test_ci_runs_the_readmes_test_command():
    commands = re.findall(r"^(make \w+)\s+#", README, re.M)
    assert commands == ["make demo", "make test"]
    run = (ROOT / ".ci" / "run").read_text()
    assert [
        line for line in run.splitlines() if line and not line.startswith(("#", "set", "cd"))
    ] == ["make test"]
