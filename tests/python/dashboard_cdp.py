"""Drive the dashboard in headless Chromium over the DevTools protocol (tests/dashboard_browser.rs).

Usage: dashboard_cdp.py CHROMIUM URL SCREENSHOT.png
       dashboard_cdp.py --restart CHROMIUM FORGEMON PORT DIR
       dashboard_cdp.py --history CHROMIUM URL SCREENSHOT.png [DIE_SET]   (the history page; see history())
       dashboard_cdp.py --page CHROMIUM URL SCREENSHOT.png [HEIGHT]   (any page, 1280 wide)

Opens URL at 1280 x 800 while the demo runs, in the time zone Asia/Kathmandu (UTC+5:45, no
daylight saving: a zone no CI machine runs in), and prints one JSON object: the first blow row
the page showed (its cells as the DOM has them), whether a row arrived while the page was open
(the live feed, not a reload), the time of day that row showed with the wall clock when it
arrived, the sources' rate cells read every 0.1 s from the first render on with the rate this
script measured from /status, the points of the curve it drew, the alert panel before and after
pressing its Acknowledge button, its reason before and after a click on it, and /status's
latched alert after that. Saves a screenshot with the alert latched. Needs the `websockets`
package (.ci/run installs it).
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
# The sources table's state and rate cells, and the header's link.
LINK = """({conn: document.getElementById('conn').textContent,
  states: Array.from(document.querySelectorAll('#sources tbody tr')).map(r => r.cells[1].textContent),
  rates: Array.from(document.querySelectorAll('#sources tbody tr')).map(r => r.cells[3].textContent)})"""
# The alert's reason: its text, title, whether the panel cuts it, and whether it is on top
# and inside the window.
REASON = """(() => { const r = document.getElementById('alert-reason'), b = r.getBoundingClientRect();
  const top = document.elementFromPoint(b.left + b.width / 2, b.top + b.height / 2);
  return {text: r.textContent, title: r.title, cut: r.scrollHeight > r.clientHeight + 1,
          on_top: r === top || r.contains(top), inside: b.top >= 0 && b.bottom <= window.innerHeight,
          expanded: r.getAttribute('aria-expanded')}; })()"""
# The time zone the page runs in, and its offset from UTC, s.
ZONE, ZONE_OFFSET_S = "Asia/Kathmandu", 5 * 3600 + 45 * 60


def time_of_day_s(text):
    """'14:03:27.4' as seconds since midnight."""
    h, m, s = text.split(":")
    return int(h) * 3600 + int(m) * 60 + float(s)


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
            time.sleep(1.5)  # a poll of the state fails too: the page has had every chance to disagree
            gone = p.eval(LINK)
            second = demo("b", "1.0")
            p.wait(f"document.getElementById('conn').textContent === 'live' && {MAX_BLOW} >= 1", "the page to reconnect",
                   timeout_s=30)
            time.sleep(0.2)
            after = p.eval(f"({{max_blow: {MAX_BLOW}, header_blows: document.getElementById('blows-total').textContent}})")
            back = p.eval(LINK)
            status = json.load(urllib.request.urlopen(url + "status"))
            print(json.dumps({"max_blow_before": before, "after": after, "status_blows": status["blows"],
                              "gone": gone, "back": back}))
        finally:
            for child in (first, second, proc):
                if child:
                    child.kill()
                    child.wait()


HISTORY_TABLE = """(id) => Array.from(document.querySelectorAll('#' + id + ' tr'))
  .map(r => Array.from(r.cells).map(c => c.textContent))"""


def history(chromium, url, shot, die="D2"):
    """Open the history page at URL, wait until it has drawn, read its tables and figures,
    choose blow 3 in the I-MR chart, and save a screenshot. Prints what it saw, with the time
    from navigation to drawn (performance.now(), ms since the page's time origin)."""
    with tempfile.TemporaryDirectory(ignore_cleanup_errors=True) as profile:
        proc, ws_url = launch(chromium, profile)
        try:
            p = Page(ws_url)
            p.call("Page.enable")
            p.call("Emulation.setDeviceMetricsOverride", width=1280, height=1300, deviceScaleFactor=1, mobile=False)
            p.call("Page.navigate", url=url)
            p.wait("document.body && document.body.dataset.ready", "the history page to draw", timeout_s=60)
            drawn = p.eval("({ready: document.body.dataset.ready, error: document.getElementById('error').textContent,"
                           " drawn: window.historyDrawn, at_ms: performance.now(),"
                           " blows: document.getElementById('h-blows').textContent,"
                           " imr: document.getElementById('imr-figures').textContent})")
            drawn["load_ms"] = p.eval("window.historyDrawn && window.historyDrawn.at")
            drawn["by_die"] = p.eval(f"({HISTORY_TABLE})('by-die')")
            drawn["by_lot"] = p.eval(f"({HISTORY_TABLE})('by-lot')")
            p.eval("(() => { const s = document.getElementById('imr-blow'); s.value = '3';"
                   " s.dispatchEvent(new Event('change')); })()")
            drawn["imr_blow_3"] = p.eval("document.getElementById('imr-figures').textContent")
            # The filter form: one die set only.
            p.eval(f"document.getElementById('f-die').value = '{die}';"
                   " document.getElementById('filters').requestSubmit()")
            p.wait("document.body.dataset.ready === '1' && document.getElementById('by-die').rows.length === 1",
                   f"the page filtered to die set {die}")
            drawn["filtered"] = {"blows": p.eval("document.getElementById('h-blows').textContent"),
                                 "by_die": p.eval(f"({HISTORY_TABLE})('by-die')")}
            p.eval("document.getElementById('f-die').value = '';"
                   " document.getElementById('filters').requestSubmit()")
            p.wait("document.body.dataset.ready === '1' && document.getElementById('by-die').rows.length > 1",
                   "the page unfiltered")
            png = p.call("Page.captureScreenshot", format="png")["data"]
            with open(shot, "wb") as f:
                f.write(base64.b64decode(png))
            print(json.dumps(drawn))
        finally:
            proc.kill()
            proc.wait()


def page_shot(chromium, url, shot, height=None):
    """A screenshot of the page at URL, 1280 wide and as tall as the page (or `height`)."""
    with tempfile.TemporaryDirectory(ignore_cleanup_errors=True) as profile:
        proc, ws_url = launch(chromium, profile)
        try:
            p = Page(ws_url)
            p.call("Page.enable")
            p.call("Page.navigate", url=url)
            p.wait("document.readyState === 'complete'", "the page")
            h = int(height) if height else min(p.eval("document.documentElement.scrollHeight"), 4000)
            p.call("Emulation.setDeviceMetricsOverride", width=1280, height=h, deviceScaleFactor=1, mobile=False)
            time.sleep(0.3)
            png = p.call("Page.captureScreenshot", format="png")["data"]
            with open(shot, "wb") as f:
                f.write(base64.b64decode(png))
        finally:
            proc.kill()
            proc.wait()


def main():
    if sys.argv[1] == "--page":
        return page_shot(*sys.argv[2:6])
    if sys.argv[1] == "--restart":
        return restart(*sys.argv[2:6])
    if sys.argv[1] == "--history":
        return history(*sys.argv[2:6])
    chromium, url, shot = sys.argv[1:4]
    with tempfile.TemporaryDirectory(ignore_cleanup_errors=True) as profile:
        proc, ws_url = launch(chromium, profile)
        try:
            p = Page(ws_url)
            p.call("Emulation.setDeviceMetricsOverride", width=1280, height=800, deviceScaleFactor=1, mobile=False)
            p.call("Emulation.setTimezoneOverride", timezoneId=ZONE)
            p.call("Page.enable")
            p.call("Page.navigate", url=url)
            base = url.split("?")[0].rstrip("/")
            # The rate cells from the page's first render of its sources, every 0.1 s for 2 s,
            # against the rate of /status's sample count over the same time.
            p.wait("document.querySelectorAll('#sources tbody tr').length > 0", "the sources table")
            blows_at_load = p.eval(MAX_BLOW)
            s0, t0 = json.load(urllib.request.urlopen(base + "/status"))["samples"], time.monotonic()
            rates = []
            while time.monotonic() - t0 < 2.0:
                rates.extend(p.eval(LINK)["rates"])
                time.sleep(0.1)
            s1, t1 = json.load(urllib.request.urlopen(base + "/status"))["samples"], time.monotonic()
            p.wait("document.readyState === 'complete' && document.getElementById('conn').textContent === 'live'",
                   "the page and its event stream")
            first = p.wait(FIRST_ROW, "blow 1's row")
            # A row for a blow after the page loaded (the live feed, not the initial state),
            # and when it arrived.
            shown = max(p.eval(MAX_BLOW), blows_at_load)
            p.wait(f"{MAX_BLOW} > {shown}", "a blow's row arriving live")
            arrived_s = time.time()
            live_row = p.eval("""(() => { const tr = document.querySelector('#blows tbody tr');
              return {blow: +tr.dataset.blow, time: tr.cells[2].textContent, title: tr.cells[2].title}; })()""")
            p.wait("!!document.querySelector('#alert.latched')", "the latched alert")
            curve_points = p.eval("curve ? [curve.blow, curve.measured.t_s.length, curve.model.t_s.length] : null")
            before = p.eval(ALERT)
            advice = p.eval("({hidden: document.getElementById('advice-kv').hidden, "
                            "text: document.getElementById('advice').textContent})")
            sensors = p.eval("({text: document.getElementById('big-channels').textContent, "
                             "sd: document.getElementById('big-eff').title})")
            png = p.call("Page.captureScreenshot", format="png")["data"]
            with open(shot, "wb") as f:
                f.write(base64.b64decode(png))
            reason_before = p.eval(REASON)
            latched_reason = json.load(urllib.request.urlopen(base + "/status"))["latched_alert"]["reason"]
            p.eval("document.getElementById('alert-reason').click()")
            p.wait("document.getElementById('alert-reason').classList.contains('open')", "the reason to open")
            reason_open = p.eval(REASON)
            p.eval("document.getElementById('alert-reason').click()")
            p.eval("document.getElementById('ack').click()")
            p.wait("!!document.querySelector('#alert.acked')", "the acknowledged state")
            after = p.eval(ALERT)
            status = json.load(urllib.request.urlopen(base + "/status"))
            # The die set's count as the header shows it, once it has caught up with /status.
            p.wait(f"document.getElementById('die-life').textContent.endsWith(' {status['die_life']['blows']}')"
                   f" || +document.getElementById('blows-total').textContent > {status['blows']}", "the die count")
            dies = {"shown": p.eval("document.getElementById('die-life').textContent"),
                    "status_blows": status["die_life"]["blows"], "blows": status["blows"]}
            print(json.dumps({"first_row": first, "blows_at_load": blows_at_load, "curve": curve_points,
                              "sensors": sensors,
                              "alert_before": before, "alert_after": after, "advice": advice,
                              "status_latched_alert": status["latched_alert"],
                              "rates": rates, "rate_status_hz": (s1 - s0) / (t1 - t0),
                              "live_row": live_row, "live_row_time_s": time_of_day_s(live_row["time"])
                              if live_row["time"].count(":") == 2 else None,
                              "arrived_time_s": (arrived_s + ZONE_OFFSET_S) % 86400,
                              "reason_before": reason_before, "reason_open": reason_open,
                              "latched_reason": latched_reason, "dies": dies}))
        finally:
            proc.kill()
            proc.wait()


if __name__ == "__main__":
    main()
