"""A headless chromium that opens a page and screenshots it once it has drawn.

Used by the browser test, ``benchmarks/bench_viewer.py`` (page-ready time) and to
make the README's screenshot. Chromium runs headless with SwiftShader WebGL,
no sandbox, no network services, a throw-away profile, and is driven over the
DevTools protocol on loopback: the page is navigated to and screenshotted every
``poll`` seconds until ``drawn(image)`` holds.
"""

from __future__ import annotations

import base64
import io
import json
import os
import shutil
import subprocess
import tempfile
import time
import urllib.request

import numpy as np

from ..errors import DependencyError, Lidar2CityError

__all__ = ["find_chromium", "chromium_flags", "scene_drawn", "capture_when_drawn"]

_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def find_chromium() -> str | None:
    """The path of a chromium / chrome executable, or None."""
    for n in _NAMES:
        p = shutil.which(n)
        if p:
            return p
    return None


def chromium_flags(profile: str, *, width: int = 1280, height: int = 800) -> list[str]:
    """Headless, sandbox-less, offline flags with SwiftShader WebGL."""
    return ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
            "--disable-background-networking", "--disable-component-update", "--disable-sync",
            "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist",
            "--disable-dev-shm-usage", f"--window-size={width},{height}",
            f"--user-data-dir={profile}", "--remote-debugging-address=127.0.0.1",
            "--remote-debugging-port=0", "about:blank"]


def scene_drawn(image: np.ndarray, *, panel_fraction: float = 0.72,
                min_fraction: float = 0.01) -> bool:
    """Whether the 3-D canvas (the left ``panel_fraction`` of the page, left of the GUI
    panel) shows buildings: at least ``min_fraction`` of its pixels are saturated colours
    (the building colours; the empty canvas and the grid are white and grey)."""
    rgb = np.asarray(image)[..., :3].astype(np.int16)
    canvas = rgb[:, : int(rgb.shape[1] * panel_fraction)]
    sat = canvas.max(axis=2) - canvas.min(axis=2)
    return float((sat > 60).mean()) >= min_fraction


def _tree_cpu_seconds(root: int) -> float | None:
    """CPU seconds (user + system) used so far by process ``root`` and its descendants
    (Linux ``/proc``; None elsewhere)."""
    if not os.path.isdir("/proc"):
        return None
    tick = os.sysconf("SC_CLK_TCK")
    parent, cpu = {}, {}
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        parent[int(d)] = int(fields[1])
        cpu[int(d)] = (int(fields[11]) + int(fields[12]) + int(fields[13]) + int(fields[14])) / tick
    total, todo = 0.0, [root]
    while todo:
        p = todo.pop()
        total += cpu.get(p, 0.0)
        todo.extend(c for c, pp in parent.items() if pp == p)
    return total


def _read(path) -> str:
    try:
        with open(path, encoding="utf-8") as f:
            return f.read()
    except OSError:
        return ""


class _Devtools:
    def __init__(self, ws_url):
        from websockets.sync.client import connect

        self.ws = connect(ws_url, max_size=64 * 2**20, open_timeout=10)
        self.n = 0

    def call(self, method, timeout=20.0, **params):
        self.n += 1
        self.ws.send(json.dumps({"id": self.n, "method": method, "params": params}))
        end = time.monotonic() + timeout
        while True:
            msg = json.loads(self.ws.recv(timeout=max(0.1, end - time.monotonic())))
            if msg.get("id") == self.n:
                if "error" in msg:
                    raise Lidar2CityError(f"chromium: {method}: {msg['error'].get('message')}")
                return msg.get("result", {})

    def close(self):
        self.ws.close()


def capture_when_drawn(url: str, *, timeout: float = 30.0, poll: float = 0.25,
                       drawn=scene_drawn, width: int = 1280, height: int = 800,
                       chromium: str | None = None):
    """Open ``url`` in headless chromium; return ``(png bytes, seconds, drawn)``.

    ``seconds`` runs from the navigation to the first screenshot for which
    ``drawn(image array)`` holds (or to ``timeout``, with ``drawn`` False).
    ``capture_when_drawn.last_cpu`` is then the CPU seconds chromium's processes used
    (Linux), a figure less dependent on the machine's load than ``seconds``.

    Raises
    ------
    DependencyError
        When no chromium is installed.
    """
    from PIL import Image

    exe = chromium or find_chromium()
    if exe is None:
        raise DependencyError("no chromium found (apt-get install chromium)")
    profile = tempfile.mkdtemp(prefix="lidar2city-chromium-")
    proc = subprocess.Popen([exe, *chromium_flags(profile, width=width, height=height)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    dev = None
    try:
        port_file = os.path.join(profile, "DevToolsActivePort")
        end = time.monotonic() + 30.0
        while not _read(port_file).strip():
            if proc.poll() is not None or time.monotonic() > end:
                raise Lidar2CityError("chromium did not start its DevTools endpoint")
            time.sleep(0.05)
        port = int(_read(port_file).split()[0])
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10) as r:
            pages = [t for t in json.load(r) if t.get("type") == "page"]
        dev = _Devtools(pages[0]["webSocketDebuggerUrl"])
        dev.call("Emulation.setDeviceMetricsOverride", width=width, height=height,
                 deviceScaleFactor=1, mobile=False)
        t0 = time.perf_counter()
        dev.call("Page.navigate", url=url)
        png, ok = b"", False
        while True:
            try:
                shot = dev.call("Page.captureScreenshot", format="png")
            except Lidar2CityError:  # the page is between documents (navigation)
                shot = None
            if shot is not None:
                png = base64.b64decode(shot["data"])
                img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))
                if drawn(img):
                    ok = True
                    break
            if time.perf_counter() - t0 > timeout:
                break
            time.sleep(poll)
        seconds = time.perf_counter() - t0
        capture_when_drawn.last_cpu = _tree_cpu_seconds(proc.pid)
        return png, seconds, ok
    finally:
        if dev is not None:
            try:
                dev.close()
            except Exception:  # the browser is being killed anyway
                pass
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        shutil.rmtree(profile, ignore_errors=True)


capture_when_drawn.last_cpu = None
