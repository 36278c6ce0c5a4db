"""The live editor (``featurewarp edit``) in a real browser: Debian's headless Chromium driven by
Selenium (issue 11). ``make install`` installs chromium, chromium-driver and selenium.

Set FEATUREWARP_SCREENSHOT=path to keep a screenshot of the editor (``make gallery`` does,
for the README).
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request

import pytest

from test_cli import Runner

pytestmark = pytest.mark.slow

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
IMAGE = os.path.join(ROOT, "samples", "astronaut.png")
MASK = os.path.join(ROOT, "samples", "astronaut_mask.png")
CHROMIUM_FLAGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
                  "--enable-unsafe-swiftshader", "--disable-dev-shm-usage", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--window-size=1280,900"]
#: Milliseconds a pointer move takes (Selenium's default, 250, made each click and each step of
#: a drag wait a quarter of a second; the page sees the same events).
MOVE_MS = 10


def small_astronaut(folder, size=128):
    """The astronaut and its mask at ``size`` px in ``folder``: (image, mask) paths (an Export in
    a second or less, not 15)."""
    import cv2

    image, mask = str(folder / "small.png"), str(folder / "small_mask.png")
    cv2.imwrite(image, cv2.resize(cv2.imread(IMAGE), (size, size), interpolation=cv2.INTER_AREA))
    cv2.imwrite(mask, cv2.resize(cv2.imread(MASK, cv2.IMREAD_GRAYSCALE), (size, size),
                                 interpolation=cv2.INTER_NEAREST))
    return image, mask


def start_editor(tmp_path, *extra, image=IMAGE, mask=MASK):
    """``featurewarp edit`` in a subprocess; returns (process, url)."""
    process = subprocess.Popen(
        [sys.executable, "-m", "featurewarp_cli", "edit", image, "-m", mask, "--no-browser", "--port", "0",
         "--handles", str(tmp_path / "h.json"), "-o", str(tmp_path / "exported.png"), *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    url = process.stdout.readline().strip()
    assert url.startswith("http://127.0.0.1:") and "token=" in url, process.stderr.read()
    return process, url


def stop_editor(process) -> None:
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
        process.wait(timeout=10)


@pytest.fixture
def editor(tmp_path):
    """An editor of its own, for a test that changes what it holds (handles, saved files)."""
    process, url = start_editor(tmp_path)
    yield process, url
    stop_editor(process)


@pytest.fixture(scope="module")
def served_editor(tmp_path_factory):
    """One editor shared by the tests that only solve, read from it or send what it refuses (a
    page loaded afresh is a client of its own, and new handles start the solver afresh)."""
    process, url = start_editor(tmp_path_factory.mktemp("served"))
    yield process, url
    stop_editor(process)


@pytest.fixture(scope="module")
def browser():
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = "/usr/bin/chromium"
    for flag in CHROMIUM_FLAGS:
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)
    driver.set_script_timeout(300)                  # wait_for's own timeout ends its script first
    yield driver
    driver.quit()


def wait_for(driver, script, timeout=30.0):
    """Poll ``script`` (JavaScript returning a value) until it is truthy; its value. The page polls
    every 5 ms, in one WebDriver call (a call per poll cost a round trip, and 50 ms between
    them); an error the script throws fails the wait at once, as it did."""
    found = driver.execute_async_script(
        "const done = arguments[arguments.length - 1], end = performance.now() + arguments[0];"
        "const check = () => {" + script + "};"
        "(function poll() {"
        "  let value;"
        "  try { value = check(); } catch (err) { return done({error: String(err)}); }"
        "  if (value || performance.now() > end) return done({value: value === undefined ? null : value});"
        "  setTimeout(poll, 5);"
        "})();", timeout * 1000)
    if "error" in found:
        raise AssertionError(f"{script}: {found['error']}")
    if not found["value"]:
        raise AssertionError(f"timed out waiting for: {script}")
    return found["value"]


def settled(driver):
    """Wait until no solve is running or pending and the last answer is drawn; return how many
    solves have finished."""
    wait_for(driver, "return document.body.dataset.ready === '1' && !featurewarp.busy && !featurewarp.pending"
                     " && !featurewarp.frameRequested && !featurewarp.maskPosting")
    return driver.execute_script("return featurewarp.solves")


def screen(driver, point):
    """Offset from the overlay's centre (what ActionChains takes) of an input pixel position."""
    return driver.execute_script(
        "const v = featurewarp.view, o = document.getElementById('overlay');"
        "return [arguments[0] * v.scale + v.ox - o.clientWidth / 2,"
        " arguments[1] * v.scale + v.oy - o.clientHeight / 2];",
        *point)


def test_editor_add_drag_save_export(editor, browser, tmp_path):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    _, url = editor
    browser.get(url)
    settled(browser)
    overlay = browser.find_element(By.ID, "overlay")
    before = browser.execute_script("return document.getElementById('gl').toDataURL()")
    actions = ActionChains(browser, duration=MOVE_MS)
    for pin in ((30, 30), (480, 30), (30, 480)):
        x, y = screen(browser, pin)
        actions.move_to_element_with_offset(overlay, round(x), round(y)).click().perform()
        settled(browser)
    x, y = screen(browser, (470, 470))
    x2, y2 = screen(browser, (505, 500))
    chain = ActionChains(browser, duration=MOVE_MS).move_to_element_with_offset(overlay, round(x), round(y))
    chain.click_and_hold()
    for k in range(1, 6):
        chain.move_to_element_with_offset(overlay, round(x + (x2 - x) * k / 5), round(y + (y2 - y) * k / 5))
    chain.release().perform()
    settled(browser)
    status = browser.find_element(By.ID, "status").text
    assert "folds 0" in status and "features kept" in status, status
    after = browser.execute_script("return document.getElementById('gl').toDataURL()")
    assert after != before                      # the preview follows the handles

    if os.environ.get("FEATUREWARP_SCREENSHOT"):                # for the README: with the mesh shown
        browser.find_element(By.ID, "grid").click()
        settled(browser)
        browser.save_screenshot(os.environ["FEATUREWARP_SCREENSHOT"])
        browser.find_element(By.ID, "grid").click()

    browser.find_element(By.ID, "save").click()
    wait_for(browser, "return featurewarp.saved")
    saved = json.loads((tmp_path / "h.json").read_text())
    points = saved["points"]
    assert len(points) == 4
    dragged = [p for p in points if p["from"] != p["to"]]
    assert len(dragged) == 1
    scale = browser.execute_script("return featurewarp.view.scale")
    assert abs(dragged[0]["from"][0] - 470) <= 1.5 / scale + 0.5 and \
        abs(dragged[0]["from"][1] - 470) <= 1.5 / scale + 0.5
    assert abs(dragged[0]["to"][0] - 505) <= 1.5 / scale + 0.5 and abs(dragged[0]["to"][1] - 500) <= 1.5 / scale + 0.5

    browser.find_element(By.ID, "export").click()
    wait_for(browser, "return featurewarp.exported", timeout=120)
    again = tmp_path / "deform.png"                    # the command in this process (its bytes, not its process)
    run = Runner()("deform", IMAGE, again, "-m", MASK, "--handles", tmp_path / "h.json")
    assert run.code == 0, run.stderr
    assert (tmp_path / "exported.png").read_bytes() == again.read_bytes()


def test_editor_undo_delete_and_toggles(served_editor, browser):
    """Delete removes the selected handle, Undo brings it back, the aware box turns to the plain map
    (the shared editor: nothing is saved)."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    _, url = served_editor
    browser.get(url)
    settled(browser)
    overlay = browser.find_element(By.ID, "overlay")
    for pin in ((100, 100), (400, 100)):
        x, y = screen(browser, pin)
        ActionChains(browser, duration=MOVE_MS).move_to_element_with_offset(overlay, round(x), round(y)) \
            .click().perform()
        settled(browser)
    assert browser.execute_script("return featurewarp.handles.points.length") == 2
    browser.find_element(By.ID, "delete").click()          # the last added is selected
    settled(browser)
    assert browser.execute_script("return featurewarp.handles.points.length") == 1
    browser.find_element(By.ID, "undo").click()
    settled(browser)
    assert browser.execute_script("return featurewarp.handles.points.length") == 2
    browser.find_element(By.ID, "aware").click()            # plain map
    settled(browser)
    assert "plain map" in browser.find_element(By.ID, "status").text


def test_requests_need_the_token_and_the_host(served_editor):
    _, url = served_editor
    base = url.split("?")[0]
    with urllib.request.urlopen(url) as response:
        assert response.status == 200 and b"featurewarp edit" in response.read()
    for bad in (base, base + "?token=wrong", base + "state?token=x"):
        with pytest.raises(urllib.error.HTTPError) as err:
            urllib.request.urlopen(bad)
        assert err.value.code == 403
    rebound = urllib.request.Request(url, headers={"Host": "attacker.example:80"})
    with pytest.raises(urllib.error.HTTPError) as err:
        urllib.request.urlopen(rebound)
    assert err.value.code == 403
    with pytest.raises(urllib.error.HTTPError) as err:
        urllib.request.urlopen(url.replace("/?", "/../etc/passwd?"))
    assert err.value.code == 404


def test_editor_binds_loopback_only_and_stops_on_ctrl_c(tmp_path):
    from featurewarp_cli.app.editor import EditorServer

    class Nothing:
        pass

    server = EditorServer.__new__(EditorServer)
    EditorServer.__init__(server, Nothing(), 0)
    try:
        assert server.server_address[0] == "127.0.0.1"
    finally:
        server.server_close()
    process, _ = start_editor(tmp_path)
    process.send_signal(signal.SIGINT)
    assert process.wait(timeout=10) == 0
    assert "editor stopped" in process.stderr.read()


def test_editor_curve_and_border_outline(served_editor, browser):
    """Shift-drag draws a curve handle; dragging a corner marker reshapes its two sides only (the
    shared editor: nothing is saved)."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    _, url = served_editor
    browser.get(url)
    settled(browser)
    overlay = browser.find_element(By.ID, "overlay")
    points = [screen(browser, (100 + 60 * k, 300 + 5 * k)) for k in range(6)]
    chain = ActionChains(browser, duration=MOVE_MS).key_down(Keys.SHIFT)
    chain.move_to_element_with_offset(overlay, *map(round, points[0]))
    chain.click_and_hold()
    for x, y in points[1:]:
        chain.move_to_element_with_offset(overlay, round(x), round(y))
    chain.release().key_up(Keys.SHIFT).perform()
    settled(browser)
    curves = browser.execute_script("return featurewarp.handles.curves")
    assert len(curves) == 1 and len(curves[0]["from"]) >= 3
    x, y = screen(browser, (511.5, 511.5))                             # the bottom-right marker
    x2, y2 = screen(browser, (560, 540))
    ActionChains(browser, duration=MOVE_MS).move_to_element_with_offset(overlay, round(x), round(y)).click_and_hold() \
        .move_to_element_with_offset(overlay, round(x2), round(y2)).release().perform()
    settled(browser)
    border = browser.execute_script("return featurewarp.handles.border")
    assert isinstance(border, dict) and set(border) == {"right", "bottom"}, border      # a corner: its two sides
    assert abs(border["right"]["bezier"][3][0] - 560) < 3 and abs(border["right"]["bezier"][3][1] - 540) < 3
    assert border["bottom"]["bezier"][3] == border["right"]["bezier"][3]
    status = browser.find_element(By.ID, "status").text
    assert "folds 0" in status, status


def post(url, route, body: bytes, headers=None):
    """POST ``body`` to ``route`` of the editor at ``url``; (status, parsed JSON or None)."""
    base, query = url.split("?")
    request = urllib.request.Request(base.rstrip("/") + route + "?" + query, data=body, method="POST",
                                     headers={"Content-Type": "application/json", **(headers or {})})
    try:
        with urllib.request.urlopen(request) as response:
            return response.status, response.read()
    except urllib.error.HTTPError as err:
        return err.code, json.loads(err.read() or b"null")


@pytest.mark.parametrize("route, body, message", [
    ("/solve", b"[" * 100000 + b"]" * 100000, "nested too deeply"),
    ("/solve", b'{"handles": {"version": 1, "points": [{"from": [1, 2], "to": [1' + b"0" * 400 + b', 1]}]}}', "finite"),
    ("/solve", b'{"handles": {"version": 1, "points": []}}', "at least two handles"),
    ("/solve", b'{"handles": 5}', "JSON object"),
    ("/save", b'{"handles": {"version": 3}}', "version"),
    ("/solve", b"not json", "Expecting value"),
])
def test_bad_requests_get_a_json_error(served_editor, route, body, message):
    process, url = served_editor
    code, answer = post(url, route, body)
    assert code == 400 and message in answer["error"]
    assert process.poll() is None                      # still serving


def test_bad_request_headers(served_editor):
    _, url = served_editor
    code, answer = post(url, "/solve", b"{}", {"Content-Type": "text/plain"})
    assert code == 400
    code, answer = post(url, "/solve", b"{}", {"Content-Length": "abc"})
    assert code == 400


def test_edit_refuses_to_overwrite_its_inputs(tmp_path):
    """Each a usage error before any server starts (in one process with a timeout: were one not
    refused, its editor would serve until the timeout ends it)."""
    from one_process import run_commands

    refused = [["-o", IMAGE], ["-o", str(tmp_path / "x.png"), "--handles", str(tmp_path / "x.png")],
               ["--handles", MASK], ["--handles", str(tmp_path / "missing" / "h.json")],
               ["-o", str(tmp_path / "x.png"), "--save-mask", MASK], ["-o", "-"]]
    shutil.copy(MASK, tmp_path / "a.mask.png")         # the painted mask's default place is the mask
    default_clash = ["edit", IMAGE, "-m", str(tmp_path / "a.mask.png"), "--no-browser", "-o", str(tmp_path / "a.png")]
    runs = run_commands([["edit", IMAGE, "-m", MASK, "--no-browser", *args] for args in refused] + [default_clash],
                        timeout=120)
    for args, run in zip(refused, runs):
        assert run.returncode == 2 and len(run.stderr.splitlines()) == 1, (args, run.stderr)
    assert runs[-1].returncode == 2 and "the default beside -o; name another with --save-mask" in runs[-1].stderr


def test_export_saves_the_handles_and_prints_the_command_that_reproduces_it(tmp_path):
    """Export writes the handles file and prints a command that, run as printed, gives the same
    bytes (on the astronaut at 128 px: two warps of it, not of 512 px)."""
    import shlex

    image, mask = small_astronaut(tmp_path)
    process, url = start_editor(tmp_path, "--cell", "8", "--background", "black", image=image, mask=mask)
    try:
        handles = {"version": 1, "points": [{"from": [8, 8], "to": [8, 8]}, {"from": [120, 120], "to": [125, 122]}]}
        code, answer = post(url, "/export", json.dumps({"handles": handles, "mode": "rigid"}).encode())
        assert code == 200, answer
        answer = json.loads(answer)
        assert json.loads((tmp_path / "h.json").read_text())["points"][1]["to"] == [125.0, 122.0]
        command = shlex.split(answer["command"])
        assert command[:2] == ["featurewarp", "deform"] and "--cell" in command and "--background" in command
        assert "--mode" in command and "rigid" in command
        again = tmp_path / "again.png"
        command[3] = str(again)
        run = Runner()(*command[1:])                   # the printed command, run in this process
        assert run.code == 0, run.stderr
        assert again.read_bytes() == (tmp_path / "exported.png").read_bytes()
    finally:
        process.send_signal(signal.SIGINT)
        process.wait(timeout=10)


def test_posts_from_another_origin_are_refused(served_editor):
    """A page of another site cannot post to the editor, even with the token in hand."""
    _, url = served_editor
    port = url.split(":")[2].split("/")[0]
    base, query = url.split("?")
    request = urllib.request.Request(base.rstrip("/") + "/save?" + query, data=b'{"handles": {"version": 3}}',
                                     method="POST", headers={"Content-Type": "application/json",
                                                             "Origin": "http://attacker.example"})
    with pytest.raises(urllib.error.HTTPError) as err:
        urllib.request.urlopen(request)
    assert err.value.code == 403
    code, answer = post(url, "/save", b'{"handles": {"version": 3}}', {"Origin": f"http://127.0.0.1:{port}"})
    assert code == 400 and "version" in answer["error"]          # its own origin: served


def test_idle_and_surplus_connections_are_closed(monkeypatch):
    """A held connection is closed after the timeout; beyond the cap a new one is closed at once."""
    import socket

    from featurewarp_cli.app import editor as editor_module

    monkeypatch.setattr(editor_module.EditorHandler, "timeout", 0.5)
    monkeypatch.setattr(editor_module, "MAX_CONNECTIONS", 2)
    with bare_server() as server:
        held = [socket.create_connection(("127.0.0.1", server.server_port)) for _ in range(2)]
        time.sleep(0.1)
        extra = socket.create_connection(("127.0.0.1", server.server_port))
        extra.settimeout(2)
        started = time.monotonic()
        assert extra.recv(1) == b"" and time.monotonic() - started < 0.4      # closed on arrival
        for sock in held:
            sock.settimeout(5)
            assert sock.recv(1) == b""                                           # closed after 0.5 s idle
        deadline = time.monotonic() + 5           # a thread frees its slot just after closing its socket
        while server.open_connections and time.monotonic() < deadline:
            time.sleep(0.01)
        again = socket.create_connection(("127.0.0.1", server.server_port))     # slots are free again
        again.sendall(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n")
        again.settimeout(5)
        assert again.recv(12).startswith(b"HTTP/1.")
        for sock in held + [extra, again]:
            sock.close()


def test_a_trickled_request_is_cut_off(monkeypatch):
    """Each byte within the socket timeout (0.1 s apart, the timeout 1 s), the whole request not
    within the deadline (0.5 s): closed by the deadline, long before the client stops sending (at
    4 s, after which the socket timeout alone would close it)."""
    import socket

    from featurewarp_cli.app import editor as editor_module

    monkeypatch.setattr(editor_module.EditorHandler, "timeout", 1.0)
    monkeypatch.setattr(editor_module, "REQUEST_DEADLINE", 0.5)
    with bare_server() as server:
        sock = socket.create_connection(("127.0.0.1", server.server_port))
        started, closed = time.monotonic(), False
        for byte in b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: " + b"a" * 100:
            try:
                sock.sendall(bytes([byte]))
            except OSError:
                closed = True
                break
            time.sleep(0.1)
            if time.monotonic() - started > 4:
                break
        sock.settimeout(3)
        try:
            closed = closed or sock.recv(1) == b""
        except OSError:
            closed = True
        assert closed and time.monotonic() - started < 2.5
        sock.close()


@contextlib.contextmanager
def bare_server():
    """An EditorServer with no session, serving in a thread (for connection-level tests)."""
    import threading

    from featurewarp_cli.app import editor as editor_module

    class Nothing:
        pass

    server = editor_module.EditorServer.__new__(editor_module.EditorServer)
    editor_module.EditorServer.__init__(server, Nothing(), 0)
    threading.Thread(target=server.serve_forever, args=(0.05,), daemon=True).start()    # shutdown() within 50 ms
    try:
        yield server
    finally:
        server.shutdown()
        server.server_close()
