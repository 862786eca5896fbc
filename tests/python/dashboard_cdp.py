"""Drive the dashboard in headless Chromium over the DevTools protocol (tests/dashboard_browser.rs).

Usage: dashboard_cdp.py CHROMIUM URL SCREENSHOT.png
       dashboard_cdp.py --restart CHROMIUM FORGEMON PORT DIR

Opens URL at 1280 x 800 while the demo runs, and prints one JSON object: the first blow row
the page showed (its cells as the DOM has them), whether a row arrived while the page was open
(the live feed, not a reload), the points of the curve it drew, the alert panel before and after
pressing its Acknowledge button, and /status's latched alert after that. Saves a screenshot
with the alert latched. Needs the `websockets` package (.ci/run installs it).
"""

import base64
import json
import os
import subprocess
import sys
import tempfile
import time
import urllib.request

from websockets.sync.client import connect


class Page:
    def __init__(self, ws_url):
        self.ws = connect(ws_url, max_size=64 * 1024 * 1024, open_timeout=30)
        self.next_id = 0

    def call(self, method, **params):
        self.next_id += 1
        self.ws.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv(timeout=30))
            if msg.get("id") == self.next_id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg["result"]

    def eval(self, expr):
        r = self.call("Runtime.evaluate", expression=expr, returnByValue=True)
        return r["result"].get("value")

    def wait(self, expr, what, timeout_s=20.0):
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            v = self.eval(expr)
            if v:
                return v
            time.sleep(0.05)
        raise SystemExit(f"timed out after {timeout_s} s waiting for {what}")


def launch(chromium, profile):
    proc = subprocess.Popen(
        [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", "--no-first-run",
         "--remote-debugging-port=0", f"--user-data-dir={profile}", "--window-size=1280,800", "about:blank"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    port_file = os.path.join(profile, "DevToolsActivePort")
    deadline = time.monotonic() + 30
    while not (os.path.exists(port_file) and open(port_file).read().count("\n") >= 1):
        if time.monotonic() > deadline or proc.poll() is not None:
            proc.kill()
            raise SystemExit(f"{chromium} did not open its DevTools port")
        time.sleep(0.05)
    port = int(open(port_file).read().split()[0])
    targets = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list"))
    page = next(t for t in targets if t["type"] == "page")
    return proc, page["webSocketDebuggerUrl"]


ROWS = "document.querySelectorAll('#blows tbody tr').length"
FIRST_ROW = """(() => { const tr = document.querySelector('#blows tbody tr[data-blow="1"]');
  return tr && Array.from(tr.cells).map(c => c.textContent); })()"""
MAX_BLOW = "Math.max(0, ...Array.from(document.querySelectorAll('#blows tbody tr')).map(r => +r.dataset.blow))"
ALERT = "({cls: document.getElementById('alert').className, kind: document.getElementById('alert-kind').textContent,\
 button_hidden: document.getElementById('ack').hidden})"


def restart(chromium, forgemon, port, workdir):
    """Open the page on one demo, stop it, start another on the same port: the page must
    reconnect by itself and show the new run. Prints what it saw."""
    url = f"http://127.0.0.1:{port}/"

    def demo(name, interval):
        return subprocess.Popen([forgemon, "demo", "--http", f"127.0.0.1:{port}", "--interval", interval,
                                 "--billets", "1", "--dir", os.path.join(workdir, name)],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    first = demo("a", "0.3")
    with tempfile.TemporaryDirectory(ignore_cleanup_errors=True) as profile:
        proc, ws_url = launch(chromium, profile)
        second = None
        try:
            p = Page(ws_url)
            p.call("Page.enable")
            deadline = time.monotonic() + 20
            while True:  # the demo's port may not listen yet
                p.call("Page.navigate", url=url)
                time.sleep(0.3)
                if p.eval("!!document.getElementById('conn')") or time.monotonic() > deadline:
                    break
            p.wait(f"{MAX_BLOW} >= 6", "six blows of the first run")
            first.kill()
            first.wait()
            before = p.eval(MAX_BLOW)
            p.wait("document.getElementById('conn').textContent !== 'live'", "the page to see the service gone")
            second = demo("b", "1.0")
            p.wait(f"document.getElementById('conn').textContent === 'live' && {MAX_BLOW} >= 1", "the page to reconnect",
                   timeout_s=30)
            time.sleep(0.2)
            after = p.eval(f"({{max_blow: {MAX_BLOW}, header_blows: document.getElementById('blows-total').textContent}})")
            status = json.load(urllib.request.urlopen(url + "status"))
            print(json.dumps({"max_blow_before": before, "after": after, "status_blows": status["blows"]}))
        finally:
            for child in (first, second, proc):
                if child:
                    child.kill()
                    child.wait()


def main():
    if sys.argv[1] == "--restart":
        return restart(*sys.argv[2:6])
    chromium, url, shot = sys.argv[1:4]
    with tempfile.TemporaryDirectory(ignore_cleanup_errors=True) as profile:
        proc, ws_url = launch(chromium, profile)
        try:
            p = Page(ws_url)
            p.call("Emulation.setDeviceMetricsOverride", width=1280, height=800, deviceScaleFactor=1, mobile=False)
            p.call("Page.enable")
            p.call("Page.navigate", url=url)
            p.wait("document.readyState === 'complete' && document.getElementById('conn').textContent === 'live'",
                   "the page and its event stream")
            blows_at_load = p.eval(MAX_BLOW)
            first = p.wait(FIRST_ROW, "blow 1's row")
            # A row for a blow after the page loaded: the live feed, not the initial state.
            p.wait(f"{MAX_BLOW} > {blows_at_load}", "a blow's row arriving live")
            p.wait("!!document.querySelector('#alert.latched')", "the latched alert")
            curve_points = p.eval("curve ? [curve.blow, curve.measured.t_s.length, curve.model.t_s.length] : null")
            before = p.eval(ALERT)
            advice = p.eval("({hidden: document.getElementById('advice-kv').hidden, "
                            "text: document.getElementById('advice').textContent})")
            png = p.call("Page.captureScreenshot", format="png")["data"]
            with open(shot, "wb") as f:
                f.write(base64.b64decode(png))
            p.eval("document.getElementById('ack').click()")
            p.wait("!!document.querySelector('#alert.acked')", "the acknowledged state")
            after = p.eval(ALERT)
            base = url.split("?")[0].rstrip("/")
            status = json.load(urllib.request.urlopen(base + "/status"))
            print(json.dumps({"first_row": first, "blows_at_load": blows_at_load, "curve": curve_points,
                              "alert_before": before, "alert_after": after, "advice": advice,
                              "status_latched_alert": status["latched_alert"]}))
        finally:
            proc.kill()
            proc.wait()


if __name__ == "__main__":
    main()
