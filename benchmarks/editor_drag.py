"""Issue 23's recorded drags through the editor's server at 1 MP (``make bench``, section ``drag``).

A ``featurewarp edit`` process serves the 1 MP photo and mask; a client replays drags as the
page does: pointer positions arrive at 60 Hz along a straight line for one second, at most
one solve is in flight, and each answer is followed by one request for the newest position
(``drag: true``), then one unmarked request at the release. Per drag it records every
update's wall time (request to answer, over HTTP on 127.0.0.1; p50/p95/max over the updates
while dragging, the release's guarded solve apart), the server's solve time,
the pointer's step between successive updates, and the settle time: from the last pointer
event to the answer for the released handle. The first solve of each handle set (the rigid
map's factorization, and the features' where their ties differ from those already factored) is
timed apart. Before the drags the client does what the page does when it opens: it loads the
state, the grid, the image and the mask, and, :data:`PLACING_S` later, solves the first two
pins (the page solves from the second handle on), then all three; those two are timed apart
too. (Until 2026-11-28 the first solve came as soon as the server printed its address: 0.3 s of
its 0.45-0.6 s was the server still starting, which a page absorbs while it loads.)

Usage::

    .venv/bin/python -m benchmarks.editor_drag [--no-drag-flag] [--browser] [--all]

``--browser`` also replays one drag in headless Chromium (as the browser tests run it) and
times how long after the release the page settles; ``--all`` replays the drags on the other
sample photos too (:data:`OTHER_PHOTOS`, each scaled to about 1 MP).
"""

from __future__ import annotations

import argparse
import http.client
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
#: Pointer events a second, and the drag's length in seconds.
RATE, SECONDS = 60, 1.0
#: Seconds between the page's load and its first solve: a person placing the first two pins.
PLACING_S = 1.0
#: Drags on a 1000 x 1000 frame (scaled to the photo): pins, the handle's start and end.
PINS = [(120, 940), (900, 940), (120, 120)]
DRAGS = {
    "onto a feature": ((850, 300), (560, 260)),           # from the background onto the head
    "towards a pin": ((500, 560), (170, 880)),            # a body point dragged onto the lower-left pin
    "a handle on a feature": ((540, 250), (760, 330)),    # the head carried
}


class Client:
    """The page's side of the protocol over one keep-alive connection."""

    def __init__(self, url: str):
        rest = url.split("//", 1)[1]
        host, query = rest.split("/", 1)
        self.query = query.lstrip("?")
        self.connection = http.client.HTTPConnection(host, timeout=600)
        self.seq = 0

    def load_page(self) -> None:
        """What the page fetches when it opens: the state, the preview grid, the image and the mask."""
        for path in ("/state", "/grid", "/image", "/mask"):
            self.connection.request("GET", path + "?" + self.query)
            response = self.connection.getresponse()
            response.read()
            if response.status != 200:
                raise RuntimeError(f"GET {path}: {response.status}")

    def solve(self, points, drag: bool) -> tuple[float, dict]:
        """(wall seconds, status) of one solve of ``points`` [(from, to), ...]."""
        self.seq += 1
        body = json.dumps({"handles": {"version": 1, "canvas": "fit",
                                       "points": [{"from": list(a), "to": list(b)} for a, b in points]},
                           "seq": self.seq, "client": "bench", "drag": drag, "mode": "similarity"})
        started = time.perf_counter()
        self.connection.request("POST", "/solve?" + self.query, body, {"Content-Type": "application/json"})
        response = self.connection.getresponse()
        data = response.read()
        seconds = time.perf_counter() - started
        if response.status != 200:
            raise RuntimeError(data.decode(errors="replace"))
        length = int.from_bytes(data[:4], "little")
        return seconds, json.loads(data[4:4 + length])


def replay(client: Client, pins, start, end, drag_flag: bool = True) -> dict:
    """One recorded drag of a handle from ``start`` to ``end`` with ``pins`` held."""
    fixed = [(p, p) for p in pins]
    first, _ = client.solve(fixed + [(start, start)], False)        # the new handle set: factored
    events = [np.asarray(start) + (np.asarray(end) - start) * k / (RATE * SECONDS)
              for k in range(1, int(RATE * SECONDS) + 1)]
    times, server, steps, sent, last = [], [], [], np.asarray(start, float), -1
    t0 = time.perf_counter()
    while True:                 # event k comes at (k + 1) / RATE s; the last one is the release
        newest = min(len(events) - 1, int((time.perf_counter() - t0) * RATE) - 1)
        if newest == last:                                      # answered before the pointer moved on
            time.sleep(max(0.0, t0 + (newest + 2) / RATE - time.perf_counter()))
            continue
        released = newest == len(events) - 1
        seconds, status = client.solve(fixed + [(start, tuple(np.round(events[newest], 3)))],
                                       drag_flag and not released)
        times.append(seconds)
        server.append(status["ms"] / 1000)
        steps.append(float(np.hypot(*(events[newest] - sent))))
        sent, last = events[newest], newest
        if released:
            settle = time.perf_counter() - (t0 + SECONDS)
            break
    dragging = times[:-1] or times                  # the last update is the release's guarded solve
    return {"first_s": first, "update_s": times, "server_s": server, "step_px": steps, "settle_s": settle,
            "p50_s": float(np.percentile(dragging, 50)), "p95_s": float(np.percentile(dragging, 95)),
            "max_s": float(np.max(dragging)), "release_s": times[-1], "updates": len(times),
            "folds": status["folds"], "warnings": status["warnings"]}


def bench_drag(photo, mask, drag_flag: bool = True) -> dict:
    """Each of :data:`DRAGS` on the photo (its size scales the 1000 x 1000 frame)."""
    import cv2

    h, w = cv2.imread(str(photo), cv2.IMREAD_GRAYSCALE).shape
    scale = np.array([(w - 1) / 999, (h - 1) / 999])
    process = subprocess.Popen([sys.executable, "-m", "featurewarp_cli", "edit", str(photo), "-m", str(mask),
                                "--no-browser", "--port", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    try:
        client = Client(process.stdout.readline().strip())
        client.load_page()
        time.sleep(PLACING_S)
        pins = [tuple(np.round(np.array(p) * scale, 1)) for p in PINS]
        placed = [client.solve([(p, p) for p in pins[:k]], False)[0] for k in (2, 3)]    # the 2nd, 3rd click
        results = {"size": [w, h], "loadavg_start": os.getloadavg(), "drag_flag": drag_flag, "pins_s": placed}
        print(f"\nRecorded drags through the editor's server, {Path(photo).name} {w}x{h}, {RATE} pointer events/s "
              f"for {SECONDS:g} s, one solve in flight (drag flag {'on' if drag_flag else 'off'})")
        print(f"  the page's first solves: two pins {placed[0] * 1000:.0f} ms, three {placed[1] * 1000:.0f} ms")
        for name, (a, b) in DRAGS.items():
            start, end = tuple(np.round(np.array(a) * scale, 1)), tuple(np.round(np.array(b) * scale, 1))
            r = replay(client, pins, start, end, drag_flag)
            results[name] = r
            print(f"  {name:22s} first {r['first_s'] * 1000:6.0f} ms · {r['updates']:3d} updates, steps "
                  f"{np.percentile(r['step_px'][1:-1] or [0], 50):4.0f} px median · update p50 "
                  f"{r['p50_s'] * 1000:5.0f} ms p95 {r['p95_s'] * 1000:5.0f} ms max {r['max_s'] * 1000:5.0f} ms · "
                  f"release {r['release_s'] * 1000:5.0f} ms, settled {r['settle_s'] * 1000:5.0f} ms after the last event · "
                  f"folds {r['folds']}")
        results["loadavg_end"] = os.getloadavg()
        return results
    finally:
        process.send_signal(signal.SIGINT)
        process.wait(timeout=30)


#: Headless Chromium as the browser tests run it (software WebGL).
CHROMIUM_FLAGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
                  "--enable-unsafe-swiftshader", "--disable-dev-shm-usage", "--window-size=1280,900"]


def browser_drag(photo, mask) -> dict:
    """The first of :data:`DRAGS` replayed in headless Chromium: 60 pointer moves over one
    second through the page; the time from the release until the page has the answer for
    the released handle drawn, and the page's counters (solves, dropped answers, frames)."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    options = webdriver.ChromeOptions()
    options.binary_location = "/usr/bin/chromium"
    for flag in CHROMIUM_FLAGS:
        options.add_argument(flag)
    process = subprocess.Popen([sys.executable, "-m", "featurewarp_cli", "edit", str(photo), "-m", str(mask),
                                "--no-browser", "--port", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    driver = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)
    idle = "return document.body.dataset.ready === '1' && !featurewarp.busy && !featurewarp.pending" \
           " && !featurewarp.frameRequested"
    try:
        driver.get(process.stdout.readline().strip())
        overlay = driver.find_element(By.ID, "overlay")
        _wait(driver, idle)
        w = driver.execute_script("return featurewarp.info.width")
        scale = (w - 1) / 999

        def offset(p):
            return [round(v) for v in driver.execute_script(
                "const v = featurewarp.view, o = document.getElementById('overlay');"
                "return [arguments[0] * v.scale + v.ox - o.clientWidth / 2,"
                " arguments[1] * v.scale + v.oy - o.clientHeight / 2];",
                p[0] * scale, p[1] * scale)]

        for pin in PINS + [DRAGS["onto a feature"][0]]:
            ActionChains(driver, duration=0).move_to_element_with_offset(overlay, *offset(pin)).click().perform()
            _wait(driver, idle)
        a, b = DRAGS["onto a feature"]
        before = driver.execute_script("return [featurewarp.solves, featurewarp.dropped, featurewarp.glDraws]")
        chain = ActionChains(driver, duration=int(1000 / RATE)).move_to_element_with_offset(overlay, *offset(a))
        chain.click_and_hold()
        for k in range(1, int(RATE * SECONDS) + 1):
            chain.move_to_element_with_offset(overlay, *offset([a[i] + (b[i] - a[i]) * k / (RATE * SECONDS)
                                                                for i in (0, 1)]))
        started = time.perf_counter()
        chain.release().perform()
        released = time.perf_counter()
        _wait(driver, idle)
        settled = time.perf_counter()
        after = driver.execute_script("return [featurewarp.solves, featurewarp.dropped, featurewarp.glDraws]")
        result = {"drag_s": released - started, "settle_s": settled - released,
                  "solves": after[0] - before[0], "dropped": after[1] - before[1], "mesh_draws": after[2] - before[2]}
        print(f"  headless Chromium, 'onto a feature': the drag's {int(RATE * SECONDS)} moves took "
              f"{result['drag_s']:.2f} s; settled {result['settle_s']:.2f} s after the release "
              f"({result['solves']} solves, {result['dropped']} answers dropped, {result['mesh_draws']} mesh draws)")
        return result
    finally:
        driver.quit()
        process.send_signal(signal.SIGINT)
        process.wait(timeout=30)


def _wait(driver, script, timeout=120.0):
    end = time.monotonic() + timeout
    while not driver.execute_script(script):
        if time.monotonic() > end:
            raise TimeoutError(script)
        time.sleep(0.02)


#: The other sample photos the drags are replayed on (``--all``; ``make bench``): a close-up
#: whose mask covers 81 % of it, a street scene, a flower cut by two edges, 24 coins.
OTHER_PHOTOS = ("closeup", "china", "dahlia", "coins")


def one_megapixel(name: str, folder: Path) -> tuple[Path, Path]:
    """samples/NAME.png and its mask scaled to about 1 MP (aspect kept) in ``folder``."""
    import cv2

    from benchmarks.inputs import upscale_mask

    image = cv2.imread(str(ROOT / "samples" / f"{name}.png"))
    h, w = image.shape[:2]
    scale = (1_000_000 / (w * h)) ** 0.5
    size = (int(round(w * scale)), int(round(h * scale)))
    photo = Path(folder) / f"{name}-1MP.png"
    cv2.imwrite(str(photo), cv2.resize(image, size, interpolation=cv2.INTER_CUBIC))
    return photo, upscale_mask(ROOT / "samples" / f"{name}_mask.png", size, Path(folder) / f"{name}-mask-1MP.png")


def bench_other_photos(drag_flag: bool = True) -> dict:
    """:func:`bench_drag` on each of :data:`OTHER_PHOTOS` at 1 MP: {name: results}."""
    with tempfile.TemporaryDirectory(prefix="featurewarp-drag-") as folder:
        return {name: bench_drag(*one_megapixel(name, Path(folder)), drag_flag) for name in OTHER_PHOTOS}


def main() -> None:
    import cv2

    from benchmarks.inputs import upscale_mask

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--no-drag-flag", action="store_true", help="send every update unmarked (full fallback)")
    parser.add_argument("--browser", action="store_true", help="also replay a drag in headless Chromium")
    parser.add_argument("--all", action="store_true", help="also replay the drags on the other sample photos")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="featurewarp-drag-") as folder:
        photo, mask = Path(folder) / "photo-1MP.png", Path(folder) / "mask-1MP.png"
        image = cv2.imread(str(ROOT / "samples" / "astronaut.png"))
        cv2.imwrite(str(photo), cv2.resize(image, (1024, 1024), interpolation=cv2.INTER_CUBIC))
        upscale_mask(ROOT / "samples" / "astronaut_mask.png", (1024, 1024), mask)
        bench_drag(photo, mask, not args.no_drag_flag)
        if args.all:
            bench_other_photos(not args.no_drag_flag)
        if args.browser:
            browser_drag(photo, mask)


if __name__ == "__main__":
    main()
