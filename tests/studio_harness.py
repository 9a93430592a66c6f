"""A studio server in a child process and a headless Chromium page on it,
for the studio's browser tests and benchmarks/studio_latency.py.

The browser is Debian's `chromium` (apt-get install chromium), driven by
Playwright's Python package (pip install playwright; no browser download:
Playwright is pointed at /usr/bin/chromium).
"""
from __future__ import annotations

import os
import queue
import shutil
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

CHROMIUM = "/usr/bin/chromium"
# flags that start it here: no sandbox (root in a container), no GPU, no
# network of its own (updates, sync, QUIC)
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync"]
STARTUP_SECONDS = 60
REPO = Path(__file__).resolve().parents[1]


def browser_missing() -> str | None:
    """Why the browser tests cannot run here, or None."""
    try:
        import playwright  # noqa: F401
    except ImportError:
        return "playwright is not installed (pip install playwright)"
    if not os.path.exists(CHROMIUM):
        return f"no {CHROMIUM} (apt-get install chromium)"
    return None


class StudioProcess:
    """`fractalc studio SCENE --no-browser --port 0 OPTIONS...`; `url` is
    the page's address it prints."""

    def __init__(self, scene: str | os.PathLike, *options: str, cwd: str | os.PathLike | None = None):
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
        self.process = subprocess.Popen([sys.executable, "-m", "fractalc", "studio", str(scene), "--no-browser",
                                         "--port", "0", *options], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                        text=True, env=env, cwd=cwd)
        lines: queue.Queue = queue.Queue()
        threading.Thread(target=lambda: lines.put(self.process.stdout.readline()), daemon=True).start()
        try:
            line = lines.get(timeout=STARTUP_SECONDS)
        except queue.Empty:
            line = ""
        if not line.startswith("fractalc studio: http"):
            self.stop()
            raise RuntimeError(f"the studio did not start: {line!r} {self.process.stderr.read()}")
        self.url = line.split(": ", 1)[1].strip()
        self.token = self.url.split("token=", 1)[1]
        self.port = int(self.url.split(":")[2].split("/")[0])

    def stop(self) -> str:
        """Stop it (SIGTERM, which `fractalc` passes on to the process
        that serves); its stderr."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=60)     # a kernel build in progress finishes first
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        return self.process.stderr.read()


class Browser:
    """Headless Chromium with a new, empty profile."""

    def __init__(self, width: int = 1280, height: int = 760):
        from playwright.sync_api import sync_playwright
        self.profile = tempfile.mkdtemp(prefix="fractalc-chromium-")
        self.playwright = sync_playwright().start()
        # bypass_csp: the page's policy forbids eval, which Playwright's waits use
        self.context = self.playwright.chromium.launch_persistent_context(
            self.profile, executable_path=CHROMIUM, headless=True, args=CHROMIUM_FLAGS, bypass_csp=True,
            viewport={"width": width, "height": height})
        self.errors: list[str] = []

    def open(self, url: str):
        page = self.context.new_page()
        page.on("pageerror", lambda error: self.errors.append(str(error)))
        page.goto(url)
        return page

    def close(self) -> None:
        self.context.close()
        self.playwright.stop()
        shutil.rmtree(self.profile, ignore_errors=True)
