"""Headless Chromium for the report tests: run it on a page, and find what shows that an injection happened or the
page misbehaved. The payloads would change ``document.title`` to "PWNED" and add a ``<pwned>`` element if they
ever ran; the word is built at run time ('PW'+'NED') so that it never appears in the escaped text."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import pytest

import bench.report.html as report_html

JS = "document.title='PW'+'NED';document.body.appendChild(document.createElement('pw'+'ned'))"
IMG = f'<img src=x onerror="{JS}">'
SCRIPT = f"<script>{JS}</script>"
TIMEOUT = 60  # s, per browser call


def chromium() -> str:
    """Path of Chromium; skipped locally when absent, a failure on CI (which installs it)."""
    path = shutil.which("chromium") or shutil.which("chromium-browser")
    if path is None:
        if os.environ.get("CI"):
            pytest.fail("chromium not found, but CI is set (CI installs chromium)")
        pytest.skip("chromium not installed")
    return path


def run_browser(tmp_path: Path, *args: str) -> tuple[str, str]:
    """Run headless Chromium; returns (stdout, stderr). Its whole process group dies on timeout."""
    profile = tmp_path / "chromium-profile"
    profile.mkdir(exist_ok=True)
    cmd = [chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
           "--no-first-run", "--disable-background-networking", "--disable-component-update",
           "--disable-sync", f"--user-data-dir={profile}", *args]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        out, err = proc.communicate(timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        pytest.fail(f"chromium took longer than {TIMEOUT} s: {' '.join(args)}")
    return out, err


class Dom(HTMLParser):
    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.tags: list[tuple[str, dict[str, str | None]]] = []
        self.title = ""
        self.summary_rows = 0
        self._where: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        self.tags.append((tag, a))
        if tag == "title":
            self._where.append("title")
        if tag == "table" and a.get("id") == "summary":
            self._where.append("summary")
        if tag == "tr" and "summary" in self._where:
            self.summary_rows += 1

    def handle_endtag(self, tag: str) -> None:
        if tag in ("title", "table") and self._where:
            self._where.pop()

    def handle_data(self, data: str) -> None:
        if self._where[-1:] == ["title"]:
            self.title += data


def problems(dom: str, stderr: str) -> list[str]:
    """Everything that shows an injection happened or the page misbehaved."""
    parsed = Dom()
    parsed.feed(dom)
    found = [line for line in stderr.splitlines() if "CONSOLE" in line or "Uncaught" in line]
    if "PWNED" in parsed.title.upper() or "PWNED" in dom.upper():   # the search keys are lower case
        found.append(f"title changed by a script: {parsed.title!r}")
    own = dom.count("<script>" + report_html.SCRIPT[:40])   # the report's own filter script (CSP hash)
    scripts = sum(1 for tag, _ in parsed.tags if tag == "script")
    if scripts > min(own, 1):
        found.append("injected element <script>")
    for tag, attrs in parsed.tags:
        if tag in ("img", "pwned", "iframe"):
            found.append(f"injected element <{tag}>")
        found += [f"event attribute {k} on <{tag}>" for k in attrs if k.startswith("on")]
    return found


def dump(tmp_path: Path, page: Path) -> tuple[str, str]:
    return run_browser(tmp_path, "--enable-logging=stderr", "--v=0", "--dump-dom", page.as_uri())
