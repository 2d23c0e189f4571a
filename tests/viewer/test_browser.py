"""A real headless browser (Debian's chromium, SwiftShader WebGL) loads the viewer and draws it;
the `view` command serves its client on loopback and nothing else."""

import subprocess
import sys
import time
import urllib.error
import urllib.request

import numpy as np
import pytest

from lidar2city.viewer.browser import find_chromium, scene_drawn, time_page


@pytest.mark.slow
def test_headless_chromium_draws_the_buildings(viewer, tmp_path):
    if find_chromium() is None:
        pytest.skip("chromium is not installed (apt-get install chromium; .ci/run installs it)")
    url = f"http://127.0.0.1:{viewer.port}"
    expect = viewer.scene_nodes()
    assert "/points" in expect and len(expect) == 1 + len(viewer.groups["2.2"])
    t = time_page(url, expect, timeout=60.0)
    (tmp_path / "viewer.png").write_bytes(t.png)
    assert t.page_complete is not None, f"not drawn in 60 s (screenshot in {tmp_path})"
    assert 0 < t.page_booted <= t.page_nodes <= t.page_complete
    assert t.wall_from_launch > t.wall_from_navigate > 0 and t.chromium_cpu > 0
    from io import BytesIO

    from PIL import Image

    img = np.asarray(Image.open(BytesIO(t.png)).convert("RGB"))
    assert img.shape[0] > 100 and img.std() > 10  # not a uniform page
    # the buildings' colours are on the canvas: the RMSE ramp's colours are saturated
    assert t.drawn and scene_drawn(img)
    # a scene node the page never gets: the probe does not call the page complete
    t = time_page(url, ["/no-such-node"], timeout=4.0)
    assert t.page_booted is not None and t.page_nodes is None and t.page_complete is None


def test_drawn_is_false_for_a_blank_page():
    assert not scene_drawn(np.full((50, 80, 3), 255, dtype=np.uint8))
    grey = np.full((50, 80, 3), 200, dtype=np.uint8)
    grey[10:20, 10:20] = (200, 30, 30)
    assert scene_drawn(grey)


def test_view_command_serves_only_its_client(edit_town, port):
    proc = subprocess.Popen([sys.executable, "-m", "lidar2city.cli.main", "view",
                             str(edit_town.model), "--port", str(port), "--no-browser"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        url = f"http://127.0.0.1:{port}"
        end = time.monotonic() + 60
        while True:
            try:
                with urllib.request.urlopen(url + "/", timeout=5) as r:
                    page = r.read().decode("utf-8", "replace")
                break
            except (urllib.error.URLError, ConnectionError):
                if proc.poll() is not None or time.monotonic() > end:
                    raise AssertionError(proc.stderr.read()) from None
                time.sleep(0.3)
        assert "<html" in page.lower()
        for path in ("/../../../../etc/passwd", "/%2e%2e/%2e%2e/etc/passwd",
                     "/" + str(edit_town.model)):
            try:
                with urllib.request.urlopen(url + path, timeout=5) as r:
                    body = r.read().decode("utf-8", "replace")
            except urllib.error.HTTPError:
                continue
            assert "root:" not in body and '"CityObjects"' not in body
    finally:
        proc.terminate()
        proc.communicate(timeout=20)


_ROOF_ON_SCREEN = """(() => {
  // the centre of the highest flat roof triangle of a building mesh, in CSS pixels
  const m = window.__viserMutable, o = m.nodeRefFromName[%s];
  let mesh = null;
  o.traverse((c) => { if (c.isMesh && !mesh) mesh = c; });
  const p = mesh.geometry.attributes.position, idx = mesh.geometry.index;
  let best = -Infinity, at = null;
  for (let t = 0; t < idx.count; t += 3) {
    const v = [0, 1, 2].map((k) => o.position.clone().fromBufferAttribute(p, idx.getX(t + k)));
    const z = (v[0].z + v[1].z + v[2].z) / 3;
    if (z > best && v.every((w) => Math.abs(w.z - v[0].z) < 1e-3)) {  // a flat roof part
      best = z;
      at = v[0].clone().add(v[1]).add(v[2]).multiplyScalar(1 / 3);
    }
  }
  const local = [at.x, at.y, at.z];  // the viewer's display frame (the mesh is not moved)
  mesh.localToWorld(at);
  at.project(m.camera);
  const r = m.canvas.getBoundingClientRect();
  return JSON.stringify([r.left + (at.x + 1) / 2 * r.width, r.top + (1 - at.y) / 2 * r.height,
                         local]);
})()"""


@pytest.mark.slow
def test_a_click_in_the_page_selects_the_building_under_it(viewer):
    """A real click on a building mesh (one mesh holds several buildings): the server
    casts the click's ray and selects the building under the pointer."""
    import json

    from lidar2city.viewer import browser

    if find_chromium() is None:
        pytest.skip("chromium is not installed (apt-get install chromium; .ci/run installs it)")
    viewer.colour_by.value = "edited"  # every building the same colour: one mesh of all
    viewer.recolour()
    (ids, handle), = viewer.groups["2.2"].values()
    assert len(ids) == 4
    with browser._Browser(find_chromium(), 1280, 800) as (_, dev):
        dev.call("Page.enable")
        dev.call("Page.addScriptToEvaluateOnNewDocument",
                 source=browser.probe_script(viewer.scene_nodes()))
        dev.call("Page.navigate", url=f"http://127.0.0.1:{viewer.port}")
        end = time.monotonic() + 60
        while time.monotonic() < end:
            r = dev.call("Runtime.evaluate", returnByValue=True,
                         expression="JSON.stringify(window.__l2cTiming || null)")
            if (json.loads(r["result"].get("value") or "null") or {}).get("complete"):
                break
            time.sleep(0.2)
        r = dev.call("Runtime.evaluate", returnByValue=True,
                     expression=_ROOF_ON_SCREEN % json.dumps(handle.name))
        x, y, aim = json.loads(r["result"]["value"])
        for kind in ("mouseMoved", "mousePressed", "mouseReleased"):
            dev.call("Input.dispatchMouseEvent", type=kind, x=x, y=y, button="left",
                     clickCount=1)
        end = time.monotonic() + 20
        while viewer.selected is None and time.monotonic() < end:
            time.sleep(0.1)
    # the building whose roof the page aimed at (straight down onto that roof point)
    aimed = viewer.pick((aim[0], aim[1], aim[2] + 100.0), (0.0, 0.0, -1.0))
    assert aimed in ids and viewer.selected == aimed
