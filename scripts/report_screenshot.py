#!/usr/bin/env python3
"""Render a report.html in headless Chromium to a PNG: what a user sees in the browser.

    python -m scripts.report_screenshot out/demo/report.html --out docs/report_screenshot.png --colours 64

Needs Chromium (Debian: ``apt-get install chromium``; also found as ``chromium-browser`` or
``google-chrome``; or pass ``--browser PATH``). The page is opened from the file system,
offline: the browser runs with networking extras off and a throw-away profile. Chromium's
headless ``--screenshot`` captures the window, not the whole page, so the window is made
taller than the page and the empty background below the page's end is cropped away.

Exit status 0 and the PNG's path and size on success; 1 with the reason otherwise.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image

BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
#: Flags for a headless run on a machine with no network and no display.
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",  # needed when running as root (CI containers)
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
)


def find_browser(explicit: str | None = None) -> str | None:
    """The Chromium executable to use: ``explicit`` if given, else the first on PATH."""
    if explicit:
        return explicit if Path(explicit).exists() or shutil.which(explicit) else None
    for name in BROWSERS:
        path = shutil.which(name)
        if path:
            return path
    return None


def crop_bottom_background(image: Image.Image, margin_px: int = 24) -> Image.Image:
    """Cut the rows below the last row that differs from the bottom row's colour."""
    pixels = np.asarray(image.convert("RGB"), dtype=np.int16)
    background = pixels[-1, 0]
    differs = np.any(np.abs(pixels - background) > 8, axis=(1, 2))
    rows = np.nonzero(differs)[0]
    bottom = int(rows[-1]) + 1 + margin_px if len(rows) else image.height
    return image.crop((0, 0, image.width, min(bottom, image.height)))


def screenshot(html: Path, out: Path, *, browser: str, width_px: int = 1100, height_px: int = 14000,
               colours: int = 0, timeout_s: float = 120.0) -> Path:
    """Render ``html`` with ``browser`` into ``out`` (PNG), cropped to the page; with
    ``colours`` > 0 the PNG is reduced to that many palette colours (a smaller file)."""
    with tempfile.TemporaryDirectory(prefix="fgslam-chromium-") as profile:
        raw = Path(profile) / "raw.png"
        command = [
            browser,
            *CHROMIUM_FLAGS,
            f"--user-data-dir={profile}",
            f"--window-size={width_px},{height_px}",
            f"--screenshot={raw}",
            html.resolve().as_uri(),
        ]
        result = subprocess.run(command, capture_output=True, text=True, timeout=timeout_s)
        if result.returncode != 0 or not raw.exists():
            tail = (result.stderr or result.stdout).strip().splitlines()[-3:]
            raise RuntimeError(f"{browser} exited with {result.returncode}: {' | '.join(tail)}")
        with Image.open(raw) as image:
            cropped = crop_bottom_background(image)
            if colours > 0:
                cropped = cropped.convert("RGB").quantize(colors=colours)
            out.parent.mkdir(parents=True, exist_ok=True)
            cropped.save(out, optimize=True)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("html", type=Path, help="the report.html to render")
    parser.add_argument("--out", type=Path, default=None, help="PNG to write (default: next to the HTML)")
    parser.add_argument("--browser", default=None, help="Chromium executable (default: found on PATH)")
    parser.add_argument("--width", type=int, default=1100, help="window width in pixels (default 1100)")
    parser.add_argument("--height", type=int, default=14000,
                        help="window height in pixels, more than the page (default 14000)")
    parser.add_argument("--colours", type=int, default=0,
                        help="reduce the PNG to this many palette colours, e.g. 64 (default: full colour)")
    args = parser.parse_args(argv)
    if not args.html.is_file():
        print(f"report_screenshot: no such file: {args.html}", file=sys.stderr)
        return 1
    browser = find_browser(args.browser)
    if browser is None:
        print("report_screenshot: Chromium not found; install it (Debian: apt-get install chromium) "
              "or pass --browser PATH", file=sys.stderr)
        return 1
    out = args.out or args.html.with_name("report_screenshot.png")
    try:
        screenshot(args.html, out, browser=browser, width_px=args.width, height_px=args.height,
                   colours=args.colours)
    except (RuntimeError, subprocess.TimeoutExpired) as error:
        print(f"report_screenshot: {error}", file=sys.stderr)
        return 1
    with Image.open(out) as image:
        print(f"{out}: {image.width}×{image.height} px")
    return 0


if __name__ == "__main__":
    sys.exit(main())
