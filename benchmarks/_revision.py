"""The revision a benchmark ran at (standard library only: the child processes of the
side-by-side benchmarks import it before choosing which tree's solver to load)."""
from __future__ import annotations

import subprocess
from pathlib import Path

HERE = Path(__file__).resolve().parent


def git_revision() -> str:
    """The short hash of HEAD, with "+dirty" when tracked files differ from it; "unknown"
    outside a git checkout (an exported tree)."""
    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=HERE,
                             capture_output=True, text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                               cwd=HERE, capture_output=True, text=True).stdout.strip()
        return rev + ("+dirty" if dirty else "")
    except Exception:
        return "unknown"
