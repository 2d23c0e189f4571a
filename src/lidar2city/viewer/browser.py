"""A headless chromium that opens a viser page and times it until its scene is drawn.

Used by the browser test, ``benchmarks/bench_viewer.py`` (page-ready time) and to
make the README's screenshot. Chromium runs headless with SwiftShader WebGL,
no sandbox, no network services, a throw-away profile, and is driven over the
DevTools protocol on loopback. A script installed before the page's own watches
viser's client state on every animation frame and notes, by the page's clock,
when the client booted, when every expected scene node held its geometry and the
first frame drawn after that on a fully opaque canvas; the page is then
screenshotted.
"""

from __future__ import annotations

import base64
import dataclasses
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

__all__ = ["find_chromium", "chromium_flags", "scene_drawn", "PageTiming", "probe_script",
           "time_page"]

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


class _Browser:
    """Headless chromium with a throw-away profile, driven over DevTools on loopback:
    ``with _Browser(exe, w, h) as (process, devtools):``. ``launched`` is the
    ``time.perf_counter()`` at which the process was started."""

    def __init__(self, exe, width, height):
        self.exe, self.width, self.height = exe, width, height
        self.proc = self.dev = None

    def __enter__(self):
        self.profile = tempfile.mkdtemp(prefix="lidar2city-chromium-")
        self.launched = time.perf_counter()
        self.proc = subprocess.Popen(
            [self.exe, *chromium_flags(self.profile, width=self.width, height=self.height)],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            port_file = os.path.join(self.profile, "DevToolsActivePort")
            end = time.monotonic() + 30.0
            while not _read(port_file).strip():
                if self.proc.poll() is not None or time.monotonic() > end:
                    raise Lidar2CityError("chromium did not start its DevTools endpoint")
                time.sleep(0.02)
            port = int(_read(port_file).split()[0])
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10) as r:
                pages = [t for t in json.load(r) if t.get("type") == "page"]
            self.dev = _Devtools(pages[0]["webSocketDebuggerUrl"])
            self.dev.call("Emulation.setDeviceMetricsOverride", width=self.width,
                          height=self.height, deviceScaleFactor=1, mobile=False)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self.proc, self.dev

    def __exit__(self, *exc):
        if self.dev is not None:
            try:
                self.dev.close()
            except Exception:  # the browser is being killed anyway
                pass
        self.proc.terminate()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        shutil.rmtree(self.profile, ignore_errors=True)
        return False


def _screenshot(dev):
    """The page as (png bytes, RGB array), or None while it is between documents."""
    from PIL import Image

    try:
        shot = dev.call("Page.captureScreenshot", format="png")
    except Lidar2CityError:  # the page is between documents (navigation)
        return None
    png = base64.b64decode(shot["data"])
    return png, np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))


@dataclasses.dataclass(frozen=True)
class PageTiming:
    """How long a viser page took to draw, from :func:`time_page`.

    The ``page_*`` figures are read from the page's own clock (milliseconds since
    its navigation started, ``performance.now()``), converted to seconds; the
    ``wall_*`` figures from this process's clock. ``None``: not reached in time.
    """

    #: the viser client has booted: its three.js scene exists (page clock)
    page_booted: float | None
    #: every expected scene node holds its geometry (page clock)
    page_nodes: float | None
    #: the first frame rendered after that, with the canvas fully opaque (page clock)
    page_complete: float | None
    #: Page.navigate sent -> page_complete seen (wall)
    wall_from_navigate: float | None
    #: chromium process launched -> page_complete seen (wall; includes browser start-up)
    wall_from_launch: float | None
    #: chromium process launched -> its DevTools endpoint answered (wall)
    wall_browser_start: float
    #: CPU seconds (user + system) of chromium's processes at the end (Linux; else None)
    chromium_cpu: float | None
    #: with ``spin``: page milliseconds per frame while the camera turns (else None)
    frame_ms: float | None
    #: the final screenshot shows buildings (:func:`scene_drawn`)
    drawn: bool
    #: that screenshot (PNG bytes)
    png: bytes


# Installed before the page's own scripts: on every animation frame, look up the expected
# scene nodes in viser's client state (window.__viserMutable, which viser exposes for its
# end-to-end tests). ``nodes``: each holds a mesh or point geometry with vertices;
# ``complete``: the renderer's first frame (three.js WebGLInfo.render.frame) after that
# moment in which the canvas is fully opaque (viser keeps the canvas at 5 % opacity
# until its environment map is ready, then fades it in).
_PROBE = """(() => {
  const expect = %s;
  const out = window.__l2cTiming = {booted: null, nodes: null, complete: null,
                                     frameMs: null};
  const filled = (o) => {
    let n = 0;
    o.traverse((c) => { const g = c.geometry;
      if (g && g.attributes && g.attributes.position) n += g.attributes.position.count; });
    return n > 0;
  };
  // a name ending in "/" stands for every node received under it (at least one)
  const wanted = () => {
    const tree = window.__viserSceneTree ? window.__viserSceneTree.getState() : {};
    const have = Object.keys(tree).filter((k) => tree[k]);
    const out = [];
    for (const e of expect) {
      if (!e.endsWith("/")) { out.push(e); continue; }
      const got = have.filter((k) => k.startsWith(e));
      if (!got.length) return null;
      out.push(...got);
    }
    return out;
  };
  let seenAt = null, ticks = 0;
  // frames the renderer drew (viser's test hook), else this loop's own frames
  const frame = () => {
    const tp = window.__viserTestpoints;
    return tp && tp.rendererInfo ? tp.rendererInfo.render.frame : ticks;
  };
  const tick = () => {
    ticks += 1;
    const m = window.__viserMutable;
    if (m && m.scene && out.booted === null) out.booted = performance.now();
    const names = m && seenAt === null ? wanted() : null;
    if (names && names.every((n) => m.nodeRefFromName[n] && filled(m.nodeRefFromName[n]))) {
      seenAt = frame();
      out.nodes = performance.now();
    }
    if (seenAt !== null && frame() > seenAt && m.canvas &&
        parseFloat(getComputedStyle(m.canvas).opacity) >= 0.999) {
      out.complete = performance.now();
      performance.mark("lidar2city-scene-complete");
      if (%s > 0) requestAnimationFrame(spin);
      return;
    }
    requestAnimationFrame(tick);
  };
  // then the frame time with the whole scene in view: the camera turned a little every
  // animation frame for %s s (a redraw each time), page milliseconds per rendered frame
  let spinFrom = null, spinFrame = null;
  const spin = () => {
    const m = window.__viserMutable;
    if (m && m.cameraControl) m.cameraControl.rotate(0.01, 0, false);
    if (m && m.requestRender) m.requestRender();
    const now = performance.now();
    if (spinFrom === null) { spinFrom = now; spinFrame = frame(); }
    else if (now - spinFrom >= %s * 1000) {
      const n = frame() - spinFrame;
      out.frameMs = n > 0 ? (now - spinFrom) / n : null;
      return;
    }
    requestAnimationFrame(spin);
  };
  requestAnimationFrame(tick);
})();"""


def probe_script(expect, spin: float = 0.0) -> str:
    """The page script that times the scene (see :func:`time_page`), to install before
    the page's own scripts: it fills ``window.__l2cTiming``."""
    return _PROBE % (json.dumps(list(expect)), float(spin), float(spin), float(spin))


def time_page(url: str, expect, *, timeout: float = 60.0, poll: float = 0.05,
              width: int = 1280, height: int = 800, settle: float = 0.0,
              spin: float = 0.0, chromium: str | None = None) -> PageTiming:
    """Open ``url`` (a viser page) in headless chromium and time it until drawn.

    Parameters
    ----------
    url : str
    expect : sequence of str
        Names of the scene nodes (e.g. ``"/lod22/2a788e"``, ``"/points"``) that make the
        scene complete; each must hold geometry with vertices. A name ending in ``/``
        (``"/lod22/"``) stands for every node the page has received under it, at
        least one.
    timeout : float
        Seconds after the navigation to give up (the result then has ``None`` times).
    poll : float
        Seconds between reads of the page's state (a cheap ``Runtime.evaluate``;
        unlike screenshots these take no time from the page's drawing).
    settle : float
        Seconds to wait, once timed, before the screenshot (for a picture of the page
        at rest: its control panel animates as it opens).
    spin : float
        When > 0: once drawn, turn the camera a little every animation frame for this
        many seconds and report the page's milliseconds per rendered frame
        (``frame_ms``: how fluid the page is with the whole scene in view).

    Returns
    -------
    PageTiming
        The page clock's figures, the wall figures, chromium's CPU seconds and a
        screenshot taken once the scene is complete.

    Raises
    ------
    DependencyError
        When no chromium is installed.
    """
    exe = chromium or find_chromium()
    if exe is None:
        raise DependencyError("no chromium found (apt-get install chromium)")
    browser = _Browser(exe, width, height)
    with browser as (proc, dev):
        started = time.perf_counter() - browser.launched
        dev.call("Page.enable")  # (without it the script below is not installed)
        dev.call("Page.addScriptToEvaluateOnNewDocument", source=probe_script(expect, spin))
        t0 = time.perf_counter()
        dev.call("Page.navigate", url=url)
        got, seen = {}, None
        while time.perf_counter() - t0 < timeout:
            try:
                r = dev.call("Runtime.evaluate", expression="JSON.stringify(window.__l2cTiming)",
                             returnByValue=True)
                got = json.loads(r.get("result", {}).get("value") or "null") or {}
            except Lidar2CityError:  # between documents
                got = {}
            if got.get("complete") is not None and seen is None:
                seen = time.perf_counter()
            if seen is not None and (spin <= 0 or got.get("frameMs") is not None
                                     or time.perf_counter() - seen > spin + 10.0):
                break
            time.sleep(poll)
        cpu = _tree_cpu_seconds(proc.pid)
        time.sleep(settle)
        shot = _screenshot(dev)
    png, img = shot if shot is not None else (b"", np.zeros((1, 1, 3), np.uint8))

    def sec(ms):
        return None if ms is None else ms / 1000.0

    return PageTiming(page_booted=sec(got.get("booted")), page_nodes=sec(got.get("nodes")),
                      page_complete=sec(got.get("complete")),
                      wall_from_navigate=None if seen is None else seen - t0,
                      wall_from_launch=None if seen is None else seen - browser.launched,
                      wall_browser_start=started, chromium_cpu=cpu,
                      frame_ms=got.get("frameMs"),
                      drawn=bool(len(png)) and scene_drawn(img), png=png)
