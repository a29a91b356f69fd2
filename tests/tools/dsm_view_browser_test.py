#!/usr/bin/python3
"""End-to-end checks of dsm-view in headless Chromium, driven by the DevTools
protocol (python3-websocket), against dsm-info's pictures and JSON.

  dsm_view_browser_test.py CHECK --dsm-view EXE --dsm-info EXE --maps DIR --work DIR
                                 [--screenshots DIR]

CHECK is one of: opacity, pixel, slice, difference, views, security, usage. The maps
(DIR/a.dsm, DIR/b.dsm: the same scene built twice with different sample counts;
DIR/mtsm.dsm: a map with layers; DIR/rgb.dsm: a small RGB map) are made by the fixture (check 'maps'). Each
check starts dsm-view and Chromium itself, on the loopback address and free
ports, under --work, and stops both by their process ids. Screenshots are saved
in --screenshots (the test's artefacts; docs/dsm-view.md shows some of them).

  dsm_view_browser_test.py measure --dsm-view EXE --dsm-info EXE --maps DIR --work DIR MAP

prints the figures of docs/dsm-view.md for MAP (time to the first picture, per
tile request, dsm-info --opacity of the same level).
"""
import argparse
import base64
import http.client
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request

try:
    import websocket  # Debian's python3-websocket
    from PIL import Image  # python3-pil
except ImportError as error:  # pragma: no cover - the message is the point
    sys.exit(f"dsm_view_browser_test: {error}: install python3-websocket and python3-pil (scripts/install-deps)")

TIMEOUT = 60.0  # seconds for one wait; generous for a loaded machine


def fail(message):
    raise SystemExit(f"FAIL: {message}")


def run(command, **kwargs):
    result = subprocess.run(command, capture_output=True, text=True, timeout=120, **kwargs)
    if result.returncode != 0:
        fail(f"{' '.join(map(str, command))} exited {result.returncode}: {result.stderr.strip()}")
    return result.stdout


class Process:
    """A child started here and stopped by its process id."""

    def __init__(self, command, **kwargs):
        self.process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kwargs)

    def stop(self):
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()


class Viewer(Process):
    """dsm-view on 127.0.0.1 and a free port; url is what it printed."""

    def __init__(self, exe, maps):
        self.started = time.monotonic()
        super().__init__([exe, *maps])
        line = self.process.stdout.readline().strip()
        if not line.startswith("dsm-view: http://127.0.0.1:"):
            self.stop()
            fail(f"dsm-view printed {line!r}, stderr {self.process.stderr.read()!r}")
        self.url = line.split(" ", 1)[1]
        self.port = int(self.url.rsplit(":", 1)[1].strip("/"))

    def stop(self):
        super().stop()
        if self.process.returncode != 0:
            fail(f"dsm-view exited {self.process.returncode} on SIGTERM: {self.process.stderr.read()!r}")


def chromium_executable():
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    fail("no Chromium: install Debian's chromium (scripts/install-deps)")


class Browser(Process):
    """Headless Chromium with one page, driven over the DevTools protocol."""

    def __init__(self, work):
        self.profile = tempfile.mkdtemp(prefix="chromium-", dir=work)
        super().__init__([chromium_executable(), "--headless=new", "--no-sandbox", "--disable-gpu",
                          "--disable-dev-shm-usage", "--no-first-run", "--no-default-browser-check",
                          "--remote-debugging-address=127.0.0.1", "--remote-debugging-port=0",
                          f"--user-data-dir={self.profile}", "--window-size=1400,900",
                          "--force-device-scale-factor=1", "about:blank"],
                         # Its singleton socket directory goes to TMPDIR: inside
                         # the test's directory, removed with it.
                         env={**os.environ, "TMPDIR": work})
        port_file = os.path.join(self.profile, "DevToolsActivePort")
        deadline = time.monotonic() + TIMEOUT
        while not os.path.exists(port_file) or not open(port_file).read().strip():
            if self.process.poll() is not None or time.monotonic() > deadline:
                self.stop()
                fail(f"Chromium did not start: {self.process.stderr.read()[-2000:]}")
            time.sleep(0.05)
        port = int(open(port_file).read().split()[0])
        targets = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=TIMEOUT))
        page = next(t for t in targets if t["type"] == "page")
        self.socket = websocket.create_connection(page["webSocketDebuggerUrl"], timeout=TIMEOUT,
                                                  suppress_origin=True)
        self.next_id = 0

    def call(self, method, **params):
        self.next_id += 1
        self.socket.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:
            reply = json.loads(self.socket.recv())
            if reply.get("id") == self.next_id:
                if "error" in reply:
                    fail(f"{method}: {reply['error']}")
                return reply.get("result", {})

    def evaluate(self, expression):
        result = self.call("Runtime.evaluate", expression=expression, awaitPromise=True, returnByValue=True)
        if "exceptionDetails" in result:
            fail(f"page script {expression[:80]!r} threw: {result['exceptionDetails']}")
        return result["result"].get("value")

    def wait_for(self, expression, what):
        deadline = time.monotonic() + TIMEOUT
        while not self.evaluate(expression):
            if time.monotonic() > deadline:
                fail(f"timed out waiting for {what}")
            time.sleep(0.02)

    def open(self, url):
        self.call("Page.enable")
        self.call("Page.navigate", url=url)
        self.wait_for("window.dsmView !== undefined && document.body.dataset.firstPicture === 'drawn'",
                      "the first picture")

    def settle(self):
        """Waits until no tile is being fetched and the panels are drawn."""
        self.wait_for("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(dsmView.idle()))))",
                      "the tiles")

    def click(self, x, y, shift=False):
        for kind in ("mouseMoved", "mousePressed", "mouseReleased"):
            self.call("Input.dispatchMouseEvent", type=kind, x=x, y=y, button="left" if kind != "mouseMoved" else "none",
                      clickCount=1, modifiers=8 if shift else 0)

    def screenshot(self, path):
        if path:
            data = self.call("Page.captureScreenshot", format="png")["data"]
            with open(path, "wb") as f:
                f.write(base64.b64decode(data))

    def stop(self):
        try:
            self.socket.close()
        except Exception:
            pass
        super().stop()


def canvas_pixels(browser, panel, width, height):
    """RGBA bytes of the top-left width x height pixels of a panel's canvas."""
    data = browser.evaluate(f"""(() => {{
        const c = document.querySelector('#panel-{panel} canvas');
        return Array.from(c.getContext('2d').getImageData(0, 0, {width}, {height}).data);
    }})()""")
    return bytes(data)


def panel_origin(browser, panel):
    return browser.evaluate(f"""(() => {{ const r = document.querySelector('#panel-{panel} canvas')
        .getBoundingClientRect(); return [r.left, r.top]; }})()""")


def level_size(dsm_info, map_path, level=0):
    info = json.loads(run([dsm_info, "--json", map_path]))
    return info["levels"][level]["width"], info["levels"][level]["height"]


def expect_grey_matches(rgba, picture_path, width, height, what):
    """The canvas's grey levels equal the 8-bit picture dsm-info wrote."""
    expected = Image.open(picture_path).convert("L")
    if expected.size != (width, height):
        fail(f"{what}: dsm-info's picture is {expected.size}, expected {(width, height)}")
    wrong = 0
    for y in range(height):
        for x in range(width):
            i = 4 * (y * width + x)
            if rgba[i] != expected.getpixel((x, y)) or rgba[i] != rgba[i + 1] or rgba[i] != rgba[i + 2]:
                wrong += 1
                if wrong == 1:
                    first = (x, y, rgba[i:i + 3], expected.getpixel((x, y)))
    if wrong:
        fail(f"{what}: {wrong} of {width * height} pixels differ from dsm-info's; first at {first[:2]}: "
             f"view {tuple(first[2])}, dsm-info {first[3]}")


def show_level0_at_one_to_one(browser):
    browser.evaluate("dsmView.state.level = '0', dsmView.setView(1, 0, 0)")
    browser.settle()


# ---------------------------------------------------------------------------
# Checks


def check_opacity(args, browser, viewer):
    a = os.path.join(args.maps, "a.dsm")
    width, height = level_size(args.dsm_info, a)
    browser.open(viewer.url)
    show_level0_at_one_to_one(browser)
    picture = os.path.join(args.work, "opacity.png")
    run([args.dsm_info, "--opacity", "-o", picture, a])
    expect_grey_matches(canvas_pixels(browser, 0, width, height), picture, width, height, "opacity view")
    browser.evaluate("dsmView.fit()")
    browser.settle()
    browser.screenshot(shot(args, "opacity"))
    # An RGB map: as colour, and one channel in grey.
    rgb = os.path.join(args.maps, "rgb.dsm")
    width, height = level_size(args.dsm_info, rgb)
    picture = os.path.join(args.work, "opacity-rgb.png")
    run([args.dsm_info, "--opacity", "-o", picture, rgb])
    expected = Image.open(picture).convert("RGB")
    colour_viewer = Viewer(args.dsm_view, [rgb])
    try:
        browser.open(colour_viewer.url)
        if browser.evaluate("document.getElementById('channel-box').hidden"):
            fail("an RGB map, but no channel menu")
        show_level0_at_one_to_one(browser)
        rgba = canvas_pixels(browser, 0, width, height)
        for y in range(height):
            for x in range(width):
                i = 4 * (y * width + x)
                if tuple(rgba[i:i + 3]) != expected.getpixel((x, y)):
                    fail(f"RGB opacity at {x},{y}: view {tuple(rgba[i:i + 3])}, dsm-info {expected.getpixel((x, y))}")
        browser.evaluate("document.getElementById('channel').value = '1',"
                         "document.getElementById('channel').dispatchEvent(new Event('change'))")
        browser.settle()
        green = Image.open(picture).getchannel("G")
        green_path = os.path.join(args.work, "opacity-green.png")
        green.save(green_path)
        expect_grey_matches(canvas_pixels(browser, 0, width, height), green_path, width, height, "green channel")
        if len(set(expected.getdata())) < 3 or all(len(set(p)) == 1 for p in expected.getdata()):
            fail("the RGB test map's opacity is grey: it cannot tell channels apart")
    finally:
        colour_viewer.stop()


def check_pixel(args, browser, viewer):
    a = os.path.join(args.maps, "a.dsm")
    browser.open(viewer.url)
    show_level0_at_one_to_one(browser)
    left, top = panel_origin(browser, 0)
    # The pixel with the most vertices near the middle: a real function to plot.
    counts = json.loads(run([args.dsm_info, "--json", "--stats", "--level", "0", a]))["stats"][0]
    if counts["max"] < 2:
        fail("the test map has no pixel with two vertices")
    width, height = level_size(args.dsm_info, a)
    pixels = []
    for x, y in ((width // 2, height // 2), (width // 3, height // 2 + 3)):
        browser.click(left + x + 0.3, top + y + 0.3, shift=bool(pixels))
        pixels.append((x, y))
        browser.wait_for(f"(dsmView.state.pixels || []).length === {len(pixels)}", "the pixel's function")
    plotted = browser.evaluate("dsmView.state.plotted")
    functions = {}
    for x, y in pixels:
        expected = functions[(x, y)] = json.loads(run([args.dsm_info, "--json", "--pixel", f"{x},{y}", a]))["pixel"]["vertices"]
        got = [v for v in plotted if (v["x"], v["y"]) == (x, y)]
        if [(v["z"], v["value"], v["layer"]) for v in got] != [(v["z"], v["value"], v["layer"]) for v in expected]:
            fail(f"pixel {x},{y}: plotted vertices {got[:3]}... differ from dsm-info's {expected[:3]}...")
        if not expected:
            fail(f"pixel {x},{y} is empty: choose a pixel with vertices")
    rows = browser.evaluate("document.querySelectorAll('#vertex-table tr').length")
    expected_rows = sum(len(functions[p]) + 1 for p in pixels)
    if rows != expected_rows:
        fail(f"vertex table has {rows} rows, expected {expected_rows}")
    # Hovering the plot reads out z and V.
    plot = browser.evaluate("(() => { const r = document.getElementById('plot').getBoundingClientRect();"
                            " return [r.left, r.top]; })()")
    browser.call("Input.dispatchMouseEvent", type="mouseMoved", x=plot[0] + 200, y=plot[1] + 100)
    readout = browser.evaluate("document.getElementById('plot-readout').textContent")
    if not readout.startswith("z = ") or "V = " not in readout:
        fail(f"plot readout {readout!r}")
    browser.evaluate("dsmView.fit()")
    browser.settle()
    browser.screenshot(shot(args, "pixel"))


def check_slice(args, browser, viewer):
    a = os.path.join(args.maps, "a.dsm")
    width, height = level_size(args.dsm_info, a)
    browser.open(viewer.url)
    browser.evaluate("document.getElementById('kind').value = 'slice',"
                     "document.getElementById('kind').dispatchEvent(new Event('change'))")
    for position in (300, 620):
        browser.evaluate(f"(() => {{ const s = document.getElementById('depth'); s.value = {position};"
                         f" s.dispatchEvent(new Event('input')); }})()")
        show_level0_at_one_to_one(browser)
        z = browser.evaluate("dsmView.state.sliceZ")
        shown = browser.evaluate("document.getElementById('depth-value').value")
        if float(shown) != z:
            fail(f"slider shows depth {shown}, the picture is of {z}")
        picture = os.path.join(args.work, f"slice-{position}.png")
        run([args.dsm_info, "--slice", repr(z), "-o", picture, a])
        expect_grey_matches(canvas_pixels(browser, 0, width, height), picture, width, height, f"slice at z={z}")
    browser.evaluate("dsmView.fit()")
    browser.settle()
    browser.screenshot(shot(args, "slice"))


def check_difference(args, browser, viewer):
    a, b = os.path.join(args.maps, "a.dsm"), os.path.join(args.maps, "b.dsm")
    width, height = level_size(args.dsm_info, a)
    browser.open(viewer.url)
    if browser.evaluate("document.getElementById('compare-box').hidden"):
        fail("two maps given, but no comparison control")
    browser.evaluate("document.getElementById('compare').value = 'diff',"
                     "document.getElementById('compare').dispatchEvent(new Event('change'))")
    show_level0_at_one_to_one(browser)
    # The difference's values (read out under the cursor) against dsm-info's float pictures.
    expected = []
    for path in (a, b):
        picture = os.path.join(args.work, os.path.basename(path) + ".tif")
        run([args.dsm_info, "--opacity", "-o", picture, path])
        expected.append(Image.open(picture))
    values = browser.evaluate(f"""(() => {{
        const out = [];
        for (let y = 0; y < {height}; ++y) for (let x = 0; x < {width}; ++x)
            out.push(dsmView.valuesAt(0, [x + 0.5, y + 0.5]).values[0]);
        return out;
    }})()""")
    for i, value in enumerate(values):
        x, y = i % width, i // width
        want = expected[0].getpixel((x, y)) - expected[1].getpixel((x, y))
        if abs(value - want) > 1e-6:
            fail(f"difference at {x},{y}: {value}, dsm-info's pictures give {want}")
    # What the panel draws: red for A > B, blue for A < B, scaled to the largest |A - B| seen.
    rgba = canvas_pixels(browser, 0, width, height)
    scale = browser.evaluate("dsmView.state.scaleMax")
    most = max(abs(expected[0].getpixel((x, y)) - expected[1].getpixel((x, y)))
               for y in range(height) for x in range(width))
    if abs(scale - most) > 1e-6 or most == 0:
        fail(f"difference scale {scale}, largest |A - B| {most}")
    for y in range(height):
        for x in range(width):
            d = (expected[0].getpixel((x, y)) - expected[1].getpixel((x, y))) / most
            want = (round(255 * max(0.0, min(1.0, d))), 0, round(255 * max(0.0, min(1.0, -d))))
            i = 4 * (y * width + x)
            got = tuple(rgba[i:i + 3])
            if max(abs(g - w) for g, w in zip(got, want)) > 1:
                fail(f"difference view at {x},{y}: {got}, expected {want}")
    browser.evaluate("dsmView.fit()")
    browser.settle()
    browser.screenshot(shot(args, "difference"))
    # Side by side: a click plots the pixel of both maps.
    browser.evaluate("document.getElementById('compare').value = 'side',"
                     "document.getElementById('compare').dispatchEvent(new Event('change'))")
    show_level0_at_one_to_one(browser)
    left, top = panel_origin(browser, 1)
    browser.click(left + width // 2 + 0.3, top + height // 2 + 0.3)
    browser.wait_for("dsmView.state.pixels.length === 2", "both maps' functions")
    maps = sorted(p["map"] for p in browser.evaluate("dsmView.state.pixels.map(p => ({map: p.map}))"))
    if maps != [0, 1]:
        fail(f"side by side plotted maps {maps}")
    if browser.evaluate("document.getElementById('panel-1').hidden"):
        fail("side by side shows one panel")
    browser.evaluate("dsmView.fit()")
    browser.settle()
    browser.screenshot(shot(args, "side-by-side"))


def check_views(args, browser, viewer):
    """Vertex heat map, layers, tile grid with hover statistics, soft shadow: drawn without errors."""
    mtsm = os.path.join(args.maps, "mtsm.dsm")
    browser.open(viewer.url)
    for kind in ("vertices", "layers", "tiles", "soft"):
        if kind == "soft":  # level 1: a quarter of the rays to trace
            browser.evaluate("document.getElementById('level').value = '1',"
                             "document.getElementById('level').dispatchEvent(new Event('change'))")
        browser.evaluate(f"document.getElementById('kind').value = '{kind}',"
                         "document.getElementById('kind').dispatchEvent(new Event('change'))")
        browser.settle()
        error = browser.evaluate("document.getElementById('readout').textContent")
        if error.startswith("error"):
            fail(f"{kind} view: {error}")
        if kind in ("vertices", "layers"):
            most = browser.evaluate("dsmView.state.scaleMax")
            stats = json.loads(run([args.dsm_info, "--json", "--stats", "--level",
                                    str(browser.evaluate("dsmView.state.shownLevel")), mtsm]))
            if kind == "vertices" and most != stats["stats"][0]["max"]:
                fail(f"heat map scale up to {most}, the level's most vertices per pixel are {stats['stats'][0]['max']}")
            if kind == "layers" and not 1 <= most <= json.loads(run([args.dsm_info, "--json", mtsm]))["max_layers"]:
                fail(f"layer scale up to {most}")
        if kind == "tiles":
            left, top = panel_origin(browser, 0)
            origin = browser.evaluate("(() => { const c = document.querySelector('#panel-0 canvas');"
                                      " const s = dsmView.state; return [c.width / 2 - s.centre[0] * s.zoom,"
                                      " c.height / 2 - s.centre[1] * s.zoom]; })()")
            browser.call("Input.dispatchMouseEvent", type="mouseMoved", x=left + origin[0] + 3, y=top + origin[1] + 3)
            browser.wait_for("document.getElementById('tile-stats').textContent.startsWith('tile 0,0')",
                             "the tile's statistics")
            text = browser.evaluate("document.getElementById('tile-stats').textContent")
            level = browser.evaluate("dsmView.state.shownLevel")
            tile = [t for t in json.loads(run([args.dsm_info, "--json", "--tiles", "--level", str(level), mtsm]))["tiles"]
                    if (t["tx"], t["ty"]) == (0, 0)][0]
            if f"{tile['vertices']} vertices" not in text or f"{tile['stored_bytes']} bytes stored" not in text:
                fail(f"tile statistics {text!r} differ from dsm-info's {tile}")
            if not browser.evaluate("getComputedStyle(document.getElementById('tile-stats')).display !== 'none'"):
                fail("tile statistics hidden")
        if kind == "soft":
            check_soft_values(args, browser, mtsm)
        browser.screenshot(shot(args, kind))


def reply_complete(reply):
    """True once the headers and Content-Length bytes of body have come (the
    server may keep the connection open for the next request)."""
    head, sep, body = reply.partition(b"\r\n\r\n")
    if not sep:
        return False
    for line in head.split(b"\r\n")[1:]:
        name, _, value = line.partition(b":")
        if name.strip().lower() == b"content-length":
            return len(body) >= int(value.strip())
    return False


def check_soft_values(args, browser, mtsm):
    """Once refined (64 rays), pixels of the soft-shadow view equal dsm-lookup's
    area-light answers for the receivers under the pixels' centres."""
    browser.wait_for("dsmView.state.softSamples === 64 && dsmView.idle()", "the soft shadow's last refinement")
    info = json.loads(run([args.dsm_info, "--json", mtsm]))
    radius = browser.evaluate("dsmView.state.radius")
    z = browser.evaluate("dsmView.state.sliceZ")
    level = browser.evaluate("dsmView.state.shownLevel")
    if level != 1:
        fail(f"soft shadow shown at level {level}, expected the level chosen, 1")
    scale = info["width"] / info["levels"][level]["width"]
    xmin, xmax, ymin, ymax = info["camera"]["screen_window"]
    width, height = info["levels"][level]["width"], info["levels"][level]["height"]
    pixels = [(width // 2, height // 2), (width // 4, 3 * height // 4), (1, 1)]
    points = []
    for x, y in pixels:  # the receiver under the pixel's centre, in level-0 raster units
        sx = xmin + (x + 0.5) * scale / info["width"] * (xmax - xmin)
        sy = ymax - (y + 0.5) * scale / info["height"] * (ymax - ymin)
        points += ["--point", f"{sx * z!r},{sy * z!r},{z!r}"]
    answers = run([args.dsm_lookup, mtsm, "--space", "light", "--area-light", f"disk:{radius!r}",
                   "--light-samples", "64", "--format", "json", *points]).splitlines()
    seen = set()
    for (x, y), answer in zip(pixels, answers):
        want = json.loads(answer)
        want = want.get("visibility", want.get("v"))
        want = want[0] if isinstance(want, list) else want
        got = browser.evaluate(f"dsmView.valuesAt(0, [({x} + 0.5) * {scale}, ({y} + 0.5) * {scale}]).values[0]")
        if abs(got - want) > 1e-6:
            fail(f"soft shadow at pixel {x},{y}: view {got}, dsm-lookup {want} ({answer})")
        seen.add(round(want, 3))
    if len(seen) < 2:
        fail(f"soft shadow test pixels all give {seen}: choose pixels that differ")


def http_status(port, raw):
    """Sends raw bytes to the server; returns the reply's status and body."""
    with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
        s.sendall(raw)
        reply = b""
        try:
            while not reply_complete(reply):
                chunk = s.recv(65536)
                if not chunk:
                    break
                reply += chunk
        except (socket.timeout, ConnectionResetError):
            pass
    status_line = reply.split(b"\r\n", 1)[0].decode("latin-1")
    parts = status_line.split(" ")
    return (int(parts[1]) if len(parts) > 1 and parts[1].isdigit() else None), reply


def check_security(args, viewer):
    port = viewer.port
    secret = os.path.join(args.work, "secret.txt")
    with open(secret, "w") as f:
        f.write("not to be served: 7f3a9c\n")
    host = f"Host: 127.0.0.1:{port}\r\nConnection: close\r\n".encode()
    cases = {
        "traversal": b"GET /../../../../../../etc/passwd HTTP/1.1\r\n" + host + b"\r\n",
        "encoded traversal": b"GET /%2e%2e/%2e%2e/%2e%2e/etc/passwd HTTP/1.1\r\n" + host + b"\r\n",
        "absolute path": b"GET " + secret.encode() + b" HTTP/1.1\r\n" + host + b"\r\n",
        "map as a path": b"GET /" + os.path.join(args.maps, "a.dsm").encode() + b" HTTP/1.1\r\n" + host + b"\r\n",
        "view.js via traversal": b"GET /api/../../view.js/../../etc/passwd HTTP/1.1\r\n" + host + b"\r\n",
        "map index out of range": b"GET /api/pixel?map=2&level=0&x=0&y=0 HTTP/1.1\r\n" + host + b"\r\n",
        "map given as a file name": b"GET /api/pixel?map=" + secret.encode() + b"&level=0&x=0&y=0 HTTP/1.1\r\n" + host + b"\r\n",
        "negative pixel": b"GET /api/pixel?map=0&level=0&x=-1&y=0 HTTP/1.1\r\n" + host + b"\r\n",
        "pixel outside": b"GET /api/pixel?map=0&level=0&x=99999&y=0 HTTP/1.1\r\n" + host + b"\r\n",
        "level outside": b"GET /api/picture?map=0&level=99&kind=opacity&x=0&y=0&w=1&h=1 HTTP/1.1\r\n" + host + b"\r\n",
        "picture outside": b"GET /api/picture?map=0&level=0&kind=opacity&x=4000000000&y=0&w=300&h=1 HTTP/1.1\r\n" + host + b"\r\n",
        "oversized picture": b"GET /api/picture?map=0&level=0&kind=opacity&x=0&y=0&w=65536&h=65536 HTTP/1.1\r\n" + host + b"\r\n",
        "unknown kind": b"GET /api/picture?map=0&level=0&kind=../../etc&x=0&y=0&w=1&h=1 HTTP/1.1\r\n" + host + b"\r\n",
        "soft shadow of too many rays per pixel": b"GET /api/picture?map=0&level=0&kind=soft&z=5&radius=0.1&samples=100000&x=0&y=0&w=96&h=64 HTTP/1.1\r\n" + host + b"\r\n",
        "NaN depth": b"GET /api/picture?map=0&level=0&kind=slice&z=nan&x=0&y=0&w=1&h=1 HTTP/1.1\r\n" + host + b"\r\n",
        "oversized URI": b"GET /api/maps?" + b"a" * 20000 + b" HTTP/1.1\r\n" + host + b"\r\n",
        "oversized header": b"GET /api/maps HTTP/1.1\r\n" + host + b"X-Big: " + b"b" * 20000 + b"\r\n\r\n",
        "oversized body": b"POST /api/maps HTTP/1.1\r\n" + host + b"Content-Length: 100000000\r\n\r\n" + b"c" * 65536,
        "malformed request line": b"GARBAGE\r\n\r\n",
        "no HTTP version": b"GET /\r\n\r\n",
        "binary junk": bytes(range(256)) * 4 + b"\r\n\r\n",
        "other method": b"DELETE /api/maps HTTP/1.1\r\n" + host + b"\r\n",
        "foreign Host (DNS rebinding)": f"GET /api/maps HTTP/1.1\r\nHost: evil.example:{port}\r\nConnection: close\r\n\r\n".encode(),
    }
    for name, raw in cases.items():
        status, reply = http_status(port, raw)
        if status is not None and not 400 <= status < 500:
            fail(f"{name}: status {status}, expected 4xx: {reply[:300]!r}")
        if b"root:" in reply or b"7f3a9c" in reply or b"DSM" in reply.split(b"\r\n\r\n", 1)[-1][:8]:
            fail(f"{name}: the reply holds a file's content: {reply[:300]!r}")
        if status is None and reply:
            fail(f"{name}: a reply that is not HTTP: {reply[:100]!r}")
    # The server still answers after all that.
    status, reply = http_status(port, b"GET /api/maps HTTP/1.1\r\n" + host + b"\r\n")
    if status != 200 or b'"maps"' not in reply:
        fail(f"after the bad requests /api/maps answered {status}")
    # Only the loopback address is bound.
    try:
        others = {a[4][0] for a in socket.getaddrinfo(socket.gethostname(), None, socket.AF_INET)} - {"127.0.0.1"}
    except socket.gaierror:
        others = set()
    for address in others:
        if address.startswith("127."):
            continue
        try:
            socket.create_connection((address, port), timeout=1).close()
            fail(f"dsm-view answers on {address}: it must bind 127.0.0.1 only")
        except OSError:
            pass


def measure(args):
    """The figures of docs/dsm-view.md: time from starting dsm-view to the
    first picture in the browser, per 256 x 256 tile request, and dsm-info
    --opacity of the level shown and of level 0 (one run each)."""
    (path,) = args.measure_maps
    browser = Browser(args.work)  # started first: its start-up is not dsm-view's
    started = time.monotonic()
    viewer = Viewer(args.dsm_view, [path])
    try:
        try:
            browser.open(viewer.url)
            first = time.monotonic() - started
            level = browser.evaluate("dsmView.state.shownLevel")
            tiles = browser.evaluate("dsmView.tileCount()")
            # The coarse preview came this much before the whole picture (page clock).
            page_first = browser.evaluate("dsmView.state.firstPictureMs / 1000")  # from the page's navigation
            page_maps = browser.evaluate("performance.getEntriesByType('resource')"
                                         ".find(e => e.name.endsWith('/api/maps')).responseEnd / 1000")
            preview_lead = browser.evaluate("dsmView.state.previewMs === undefined ? null :"
                                            " (dsmView.state.firstPictureMs - dsmView.state.previewMs) / 1000")
            browser.screenshot(shot(args, "measure"))
        finally:
            browser.stop()
        info = json.loads(run([args.dsm_info, "--json", path]))
        width, height = info["levels"][0]["width"], info["levels"][0]["height"]
        connection = http.client.HTTPConnection("127.0.0.1", viewer.port, timeout=60)
        times = []
        for k in range(8):  # eight level-0 tiles across the middle row
            x, y = (width // 8) * k, height // 2
            url = f"/api/picture?map=0&level=0&kind=opacity&x={x}&y={y}&w={min(256, width - x)}&h={min(256, height - y)}"
            t0 = time.monotonic()
            connection.request("GET", url)
            response = connection.getresponse()
            response.read()
            times.append(time.monotonic() - t0)
            if response.status != 200:
                fail(f"{url}: {response.status}")
        connection.close()
    finally:
        viewer.stop()
    results = {"first_picture_s": first, "first_picture_level": level, "first_picture_tiles": tiles,
               "page_navigation_to_first_picture_s": page_first, "page_navigation_to_map_list_s": page_maps,
               "coarse_preview_s": None if preview_lead is None else first - preview_lead,
               "tile_request_s": sum(times) / len(times)}
    for name, lvl in (("shown", level), ("zero", 0)):
        t0 = time.monotonic()
        run([args.dsm_info, "--opacity", "--level", str(lvl), "-o", os.path.join(args.work, f"level{lvl}.exr"), path])
        results[f"dsm_info_opacity_level_{name}_s"] = time.monotonic() - t0
    print(json.dumps(results, indent=2))


def check_usage(args):
    """Exit statuses and messages without serving anything."""
    a = os.path.join(args.maps, "a.dsm")
    not_a_map = os.path.join(args.work, "not-a-map.dsm")
    with open(not_a_map, "w") as f:
        f.write("hello\n")
    cases = [
        ([], 2, "MAP is required"),
        ([a, a, a], 2, ""),
        ([a, "--port", "70000"], 2, "--port"),
        ([a, "--bogus"], 2, "--bogus"),
        ([os.path.join(args.work, "missing.dsm")], 1, "dsm-view: ERROR '"),
        ([not_a_map], 1, f"dsm-view: ERROR '{not_a_map}'"),
        (["-"], 1, "standard input"),
    ]
    for arguments, status, message in cases:
        result = subprocess.run([args.dsm_view, *arguments], capture_output=True, text=True, timeout=30)
        if result.returncode != status or message not in result.stderr or result.stdout:
            fail(f"dsm-view {arguments}: exit {result.returncode}, stdout {result.stdout!r}, stderr {result.stderr!r}; "
                 f"expected exit {status} and {message!r}")
    # A port in use is an error of status 1, not a silent other port.
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = subprocess.run([args.dsm_view, a, "--port", str(port)], capture_output=True, text=True, timeout=30)
        if result.returncode != 1 or f"cannot listen on 127.0.0.1:{port}" not in result.stderr:
            fail(f"port {port} in use: exit {result.returncode}, stderr {result.stderr!r}")
    result = subprocess.run([args.dsm_view, "--help"], capture_output=True, text=True, timeout=30)
    if result.returncode != 0 or "--open" not in result.stdout or "docs/dsm-view.md" not in result.stdout:
        fail(f"--help: exit {result.returncode}, {result.stdout!r}")


def make_maps(args):
    os.makedirs(args.maps, exist_ok=True)
    examples = args.examples
    build = [args.dsm_build, "-q", "-t", "16", "-j", "2"]
    run(build + [os.path.join(examples, "hairball.json"), "-r", "96x64", "-s", "4", "-o", os.path.join(args.maps, "a.dsm")])
    run(build + [os.path.join(examples, "hairball.json"), "-r", "96x64", "-s", "9", "-o", os.path.join(args.maps, "b.dsm")])
    run(build + [os.path.join(examples, "area-light.json"), "-r", "64", "-s", "4", "-l", "4",
                 "-o", os.path.join(args.maps, "mtsm.dsm")])
    run([args.make_sample_map, os.path.join(args.maps, "rgb.dsm")])


def shot(args, name):
    if not args.screenshots:
        return None
    os.makedirs(args.screenshots, exist_ok=True)
    return os.path.join(args.screenshots, f"dsm-view-{name}.png")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("check")
    parser.add_argument("--dsm-view")
    parser.add_argument("--dsm-info")
    parser.add_argument("--dsm-build")
    parser.add_argument("--dsm-lookup")
    parser.add_argument("--make-sample-map")
    parser.add_argument("--examples")
    parser.add_argument("--maps", required=True)
    parser.add_argument("--work")
    parser.add_argument("--screenshots")
    parser.add_argument("measure_maps", nargs="*")
    args = parser.parse_intermixed_args()
    if args.check == "maps":
        make_maps(args)
        return
    if args.check == "measure":
        os.makedirs(args.work, exist_ok=True)
        measure(args)
        return
    shutil.rmtree(args.work, ignore_errors=True)
    os.makedirs(args.work)
    if args.check == "usage":
        check_usage(args)
        print("dsm-view usage: OK")
        return
    maps = {"difference": ["a.dsm", "b.dsm"], "views": ["mtsm.dsm"]}.get(args.check, ["a.dsm"])
    viewer = Viewer(args.dsm_view, [os.path.join(args.maps, m) for m in maps])
    browser = None
    try:
        if args.check == "security":
            check_security(args, viewer)
        else:
            browser = Browser(args.work)
            {"opacity": check_opacity, "pixel": check_pixel, "slice": check_slice,
             "difference": check_difference, "views": check_views}[args.check](args, browser, viewer)
    finally:
        if browser:
            browser.stop()
        viewer.stop()
    print(f"dsm-view {args.check}: OK")


if __name__ == "__main__":
    main()
