"""Screenshots of the built documentation at two window widths, to look at the pages as a
reader's browser shows them (tables, code blocks, mathematics) after a change of theme or
layout.

    python3 -m sphinx -b html docs docs/_build/html
    python3 docs/screenshots.py [--html docs/_build/html] [--out docs/_build/screenshots]
                                [--pages getting_started options ...]

Needs a headless Chromium (Debian: ``apt-get install chromium``); the pages are opened from
disk, with no network, so the mathematics must render from the MathJax copy in the built
site.  Writes ``<page>-<width>.png`` per page and width (1280 and 800 px).
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
WIDTHS = (1280, 800)
PAGES = ("index", "getting_started", "options", "trust", "guides/cge",
         "guides/modelling_languages", "api")


def browser() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


def shoot(exe: str, page: Path, width: int, out: Path, height: int = 2400) -> None:
    with tempfile.TemporaryDirectory() as profile:
        subprocess.run(
            [exe, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
             "--no-first-run", "--disable-background-networking", "--disable-component-update",
             "--disable-sync", f"--user-data-dir={profile}", "--hide-scrollbars",
             "--virtual-time-budget=4000",  # let MathJax typeset before the shot
             f"--window-size={width},{height}", f"--screenshot={out}", page.as_uri()],
            check=True, capture_output=True, timeout=120)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--html", type=Path, default=HERE / "_build" / "html")
    ap.add_argument("--out", type=Path, default=HERE / "_build" / "screenshots")
    ap.add_argument("--pages", nargs="+", default=list(PAGES))
    a = ap.parse_args(argv)
    exe = browser()
    if exe is None:
        print("no headless Chromium found (Debian: apt-get install chromium)", file=sys.stderr)
        return 2
    a.out.mkdir(parents=True, exist_ok=True)
    for name in a.pages:
        page = a.html / f"{name}.html"
        if not page.exists():
            print(f"{page} does not exist: build the docs first", file=sys.stderr)
            return 2
        for width in WIDTHS:
            target = a.out / f"{name.replace('/', '_')}-{width}.png"
            shoot(exe, page, width, target)
            print(target)
    return 0


if __name__ == "__main__":
    sys.exit(main())
