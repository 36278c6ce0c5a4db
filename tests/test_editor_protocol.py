"""The editor's server side of live updates (issue 23 item 2) and of its new calls, in-process:
a request overtaken by a newer one of its page is answered ``stale`` without a solve, a drag
caps the fallback, the painted mask and the density are checked."""

from __future__ import annotations

import base64
import contextlib
import json
import os
import threading
import time
import urllib.request

import cv2
import numpy as np
import pytest

from featurewarp_cli.app import editor_session
from featurewarp_cli.app.editor import EditorServer
from featurewarp_cli.app.editor_session import EditorSession, options_given
from featurewarp_cli.app.pipeline import Settings
from test_editor import small_astronaut

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
IMAGE = os.path.join(ROOT, "samples", "astronaut.png")
MASK = os.path.join(ROOT, "samples", "astronaut_mask.png")
PINS = [{"from": [60, 470], "to": [60, 470]}, {"from": [450, 470], "to": [450, 470]}]
#: Seconds between a test's server thread's looks for shutdown() (socketserver's default, 0.5 s,
#: made each server.shutdown() below wait up to half a second).
POLL = 0.05


@contextlib.contextmanager
def served(session):
    """An EditorServer of ``session`` serving in a thread while the block runs."""
    server = EditorServer(session, 0)
    threading.Thread(target=server.serve_forever, args=(POLL,), daemon=True).start()
    try:
        yield server
    finally:
        server.shutdown()
        server.server_close()


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    folder = tmp_path_factory.mktemp("session")
    return EditorSession(Settings("deform"), IMAGE, MASK, None, str(folder / "out.png"))


def request(seq, client="page", to=(150, 60), **extra):
    return {"handles": {"version": 1, "points": PINS + [{"from": [130, 60], "to": list(to)}]}, "seq": seq,
            "client": client, **extra}


@pytest.fixture
def counted(session, monkeypatch):
    """The session with its deformer's solves counted (and the fallback cap each one saw)."""
    calls = []
    solve = session.deformer.solve

    def counting(handles, mode=None, drag=False):
        calls.append((session.deformer.rigid.rigid_steps, drag))
        return solve(handles, mode, drag)

    monkeypatch.setattr(session.deformer, "solve", counting)
    session.newest.clear()
    return session, calls


def test_an_older_request_is_answered_stale_without_a_solve(counted):
    session, calls = counted
    status, positions = session.solve(request(5))
    assert status["seq"] == 5 and not status.get("stale") and len(positions) > 0
    status, positions = session.solve(request(4, to=(160, 50)))
    assert status == {"stale": True, "seq": 4} and positions == b""
    assert len(calls) == 1
    status, _ = session.solve(request(1, client="another page"))          # pages are apart
    assert not status.get("stale") and len(calls) == 2
    status, _ = session.solve({"handles": request(0)["handles"]})          # no number: always solved
    assert not status.get("stale") and len(calls) == 3


def test_a_request_overtaken_while_it_waits_for_the_solver_is_dropped(counted):
    """Two requests wait while a solve runs: only the newer one is solved."""
    session, calls = counted
    answers = {}

    def send(seq):
        answers[seq] = session.solve(request(seq, to=(150 + seq, 60)))[0]

    with session.lock:                                  # a solve in progress
        older = threading.Thread(target=send, args=(10,))
        older.start()
        wait_until(lambda: session.newest.get("page") == 10)
        newer = threading.Thread(target=send, args=(11,))
        newer.start()
        wait_until(lambda: session.newest.get("page") == 11)
    older.join(30)
    newer.join(30)
    assert answers[10] == {"stale": True, "seq": 10}
    assert answers[11]["seq"] == 11 and not answers[11].get("stale")
    assert len(calls) == 1


def wait_until(condition, timeout=10.0):
    end = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.005)


def test_a_drag_caps_the_rigid_map_and_skips_the_fold_guard_and_the_release_does_neither(counted):
    session, calls = counted
    session.solve(request(20, drag=True))
    session.solve(request(21, drag=False))
    assert calls == [(editor_session.DRAG_RIGID_STEPS, True), (editor_session.EDITOR_RIGID_STEPS, False)]


@pytest.mark.parametrize("body", [{"seq": -1}, {"seq": 1.5}, {"seq": True}, {"seq": 1, "client": 7},
                                  {"seq": 1, "client": "x" * 65}])
def test_malformed_request_numbers_are_refused(session, body):
    with pytest.raises(ValueError, match="seq must be"):
        session.solve({**request(0), **body})


def test_stale_answers_over_http(session):
    """Through the server: a stale answer is its 4-byte length and status, no positions."""
    with served(session) as server:
        session.newest.clear()

        def solve(seq):
            data = json.dumps(request(seq)).encode()
            req = urllib.request.Request(server.url.replace("/?", "/solve?"), data=data, method="POST",
                                         headers={"Content-Type": "application/json"})
            with urllib.request.urlopen(req) as response:
                body = response.read()
            length = int.from_bytes(body[:4], "little")
            start = 4 + length + (-(4 + length) % 4)            # the positions start 4-aligned
            return json.loads(body[4:4 + length]), len(body) - start

        status, rest = solve(31)
        assert status["seq"] == 31 and rest > 0 and rest % 8 == 0              # float32 x, y per node
        assert solve(30) == ({"stale": True, "seq": 30}, 0)


def test_the_painted_mask_is_checked_before_it_is_decoded(session):
    width, height = session.texture_size
    for bad, message in [("nope", "data URL"), ("data:image/png;base64,%%%", "base64"),
                         ("data:image/png;base64," + base64.b64encode(b"GIF89a" + b"0" * 40).decode(), "not a PNG")]:
        with pytest.raises(ValueError, match=message):
            session.set_mask({"png": bad})
    small = cv2.imencode(".png", np.zeros((8, 8), np.uint8))[1].tobytes()
    with pytest.raises(ValueError, match=f"texture is {width}x{height}"):
        session.set_mask({"png": "data:image/png;base64," + base64.b64encode(small).decode()})


def test_density_and_the_exact_cell_in_the_printed_command(tmp_path):
    session = EditorSession(Settings("deform"), IMAGE, MASK, None, str(tmp_path / "out.png"))
    normal = session.cell
    with pytest.raises(ValueError, match="density 'many'"):
        session.set_density({"density": "many"})
    with pytest.raises(ValueError, match="density {}"):                  # was "unhashable type: 'dict'"
        session.set_density({"density": {}})
    state = session.set_density({"density": "fewer"})
    assert state["density"] == "fewer" and state["cell"] == pytest.approx(2 * normal, abs=1e-3)
    assert options_given(Settings("deform", cell=7.8125)) == ["--cell", "7.8125"]
    assert options_given(Settings("deform", cell=1 / 3)) == ["--cell", repr(1 / 3)]


def test_a_failed_export_leaves_the_handles_file_and_the_output_as_they_were(tmp_path):
    """Export writes the handles file its printed command names (after the image): where the warp
    fails (handles that lay the image over itself), it and the output are as they were, or absent."""
    from featurewarp_cli.app.pipeline import WarpError

    image, mask = small_astronaut(tmp_path, 40)             # 40 px: 0.35 s an export (64: 0.75 s, 512: 15 s)
    crossing = {"version": 2, "points": [{"from": [8, 8], "to": [32, 8]}, {"from": [32, 8], "to": [8, 8]},
                                         {"from": [8, 32], "to": [32, 32]}, {"from": [32, 32], "to": [8, 32]}]}
    for existed in (True, False):
        out, handles = tmp_path / "out.png", tmp_path / "out.handles.json"
        for path in (out, handles):
            path.write_bytes(b"SENTINEL") if existed else path.unlink(missing_ok=True)
        session = EditorSession(Settings("deform"), image, mask, None, str(out))
        with pytest.raises(WarpError, match="nothing written"):
            session.export({"handles": crossing})
        for path in (out, handles):
            assert (path.read_bytes() == b"SENTINEL") if existed else not path.exists()
    handles.unlink(missing_ok=True)
    handles.symlink_to(tmp_path / "nowhere.json")              # dangling: the restore leaves it a link
    with pytest.raises(WarpError, match="nothing written"):
        EditorSession(Settings("deform"), image, mask, None, str(out)).export({"handles": crossing})
    assert handles.is_symlink() and not (tmp_path / "nowhere.json").exists()


def _raw(server, text: bytes, timeout=5.0) -> bytes:
    """Send raw bytes on one connection to ``server``; everything it answers until it closes."""
    import socket

    port = int(server.url.split(":")[2].split("/")[0])
    with socket.create_connection(("127.0.0.1", port), timeout=timeout) as connection:
        connection.sendall(text)
        answer = b""
        while chunk := connection.recv(65536):
            answer += chunk
    return answer


def test_refused_and_cut_short_requests_answer_json_and_leave_no_body_behind(session, monkeypatch):
    """A refused POST left its body unread on the kept-alive connection (taken as the next
    request line); Content-Length "²" got no answer at all; a body shorter than its length was
    a 500 after the socket timeout (0.5 s here: each request is sent whole at once, and the short
    body waits it out); a 5000-digit number quoted CPython's digit limit."""
    from featurewarp_cli.app import editor

    monkeypatch.setattr(editor.EditorHandler, "timeout", 0.5)
    with served(session) as server:
        port, token = server.url.split(":")[2].split("/")[0], server.url.split("token=")[1]
        head = f"Host: 127.0.0.1:{port}\r\nContent-Type: application/json\r\n"
        body = b'{"a":1}'
        follow = f"GET /state?token={token} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n".encode()
        for path in (f"/nope?token={token}", "/solve?token=wrong"):
            answer = _raw(server, f"POST {path} HTTP/1.1\r\n{head}Content-Length: 7\r\n\r\n".encode() + body + follow)
            assert answer.count(b"HTTP/1.1") == 1 and b'"error"' in answer, answer   # closed, not smuggled
        answer = _raw(server, f"POST /save?token={token} HTTP/1.1\r\n{head}Content-Length: \u00b2\r\n\r\n{{}}"
                      .encode("latin-1"))
        assert answer.startswith(b"HTTP/1.1 400") and b"Content-Length 1 to" in answer
        answer = _raw(server, f"POST /save?token={token} HTTP/1.1\r\n{head}Content-Length: 30\r\n\r\n".encode()
                      + b'{"handles":1}')
        assert answer.startswith(b"HTTP/1.1 408") and b"ended before its Content-Length" in answer
        huge = b'{"handles": {"version": 1, "points": [{"from": [' + b"9" * 5000 + b', 2], "to": [1, 2]}]}}'
        answer = _raw(server, f"POST /save?token={token} HTTP/1.1\r\n{head}Content-Length: {len(huge)}\r\n"
                      "Connection: close\r\n\r\n".encode() + huge)
        assert answer.startswith(b"HTTP/1.1 400") and b"a number is too long" in answer and b"sys." not in answer


def test_saved_handles_are_what_a_reloaded_page_starts_from_and_exports_run_one_at_a_time(tmp_path):
    """/state gave the start-up handles after a Save (a reload then saved them over the file);
    two Exports at once could leave the handles file of one beside the image of the other. (The
    astronaut at 128 px: an Export takes about 0.15 s, one that did not wait would show in 0.3 s.)"""
    image, mask = small_astronaut(tmp_path)
    session = EditorSession(Settings("deform"), image, mask, str(tmp_path / "h.json"), str(tmp_path / "out.png"))
    pins = SMALL["points"][:1] + [{"from": [100, 100], "to": [100, 100]}]
    turned = {"version": 1, "points": pins + [{"from": [30, 15], "to": [37, 15]}]}
    session.save({"handles": turned})
    assert session.state()["handles"] == json.loads((tmp_path / "h.json").read_text())
    other = {"version": 1, "points": pins + [{"from": [30, 15], "to": [25, 20]}]}
    saved = (tmp_path / "h.json").read_bytes()
    calls = [threading.Thread(target=session.export, args=({"handles": h},)) for h in (turned, other)]
    calls.append(threading.Thread(target=session.save, args=({"handles": other},)))
    held = session.files.acquire()
    for thread in calls:
        thread.start()
    time.sleep(0.3)
    assert held and not (tmp_path / "out.png").exists()           # all wait for the one holding the files
    assert (tmp_path / "h.json").read_bytes() == saved
    session.files.release()
    for thread in calls:
        thread.join()
    written = json.loads((tmp_path / "h.json").read_text())
    assert written["points"][2]["to"] in ([37, 15], [25, 20]) and session.state()["handles"] == written


def _post(server, route: str, body: dict) -> tuple[int, dict]:
    """POST ``body`` as JSON to ``route`` of ``server``: the status and the JSON answer."""
    req = urllib.request.Request(server.url.replace("/?", f"/{route}?"), data=json.dumps(body).encode(),
                                 method="POST", headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=60) as response:
            return response.status, json.loads(response.read())
    except urllib.error.HTTPError as err:
        return err.code, json.loads(err.read())


@pytest.mark.parametrize("cell", [1.0, 1.5])
def test_more_density_at_the_finest_cell_keeps_export_working(tmp_path, cell):
    """Hostile review D8: started with --cell 1 (or 1.5), "more" asked for a 0.5 px cell: 400
    'cell must be ... at least 1, not 0.5', but the session had stored it, and every later
    Export failed the same way. The cell stops at 1 px; Export writes."""
    image, mask = small_astronaut(tmp_path, 64)
    session = EditorSession(Settings("deform", cell=cell), image, mask, None, str(tmp_path / "out.png"))
    with served(session) as server:
        status, state = _post(server, "density", {"density": "more"})
        assert status == 200 and state["density"] == "more" and state["cell"] >= 1.0, state
        handles = {"version": 1, "points": [{"from": [2, 2], "to": [2, 2]}, {"from": [40, 40], "to": [45, 42]}]}
        status, answer = _post(server, "export", {"handles": handles})
        assert status == 200 and answer["exported"] == str(tmp_path / "out.png"), answer
        assert cv2.imread(str(tmp_path / "out.png")) is not None


def test_a_density_that_fails_leaves_the_session_as_it_was(session, monkeypatch):
    """Where the new density's mesh cannot be built, the answer is the error and the session keeps
    its density, cell and deformer (it stored the new ones first)."""
    from featurewarp_cli.engine import deform

    before = session.density, session.cell, session.deformer

    def refuse(*args, **kwargs):
        raise ValueError("no mesh here")

    monkeypatch.setattr(deform, "Deformer", refuse)
    with pytest.raises(ValueError, match="no mesh here"):
        session.set_density({"density": "fewer"})
    assert (session.density, session.cell, session.deformer) == before


@pytest.mark.parametrize("shape", [(1, 10000), (10000, 1)])
def test_a_long_strip_opens_in_the_editor(tmp_path, shape):
    """Hostile review D5: a 10000 x 1 image scaled to the 4096 px texture had no row left, and
    'edit' stopped on OpenCV's '(-215:Assertion failed) !dsize.empty()'. Each side keeps 1 px."""
    cv2.imwrite(str(tmp_path / "strip.png"), np.full(shape + (3,), 128, np.uint8))
    session = EditorSession(Settings("deform"), str(tmp_path / "strip.png"), None, None, None)
    assert session.texture_size == ((4096, 1) if shape[0] == 1 else (1, 4096))
    assert cv2.imdecode(np.frombuffer(session.image_png, np.uint8), cv2.IMREAD_UNCHANGED).shape[:2] == \
        session.texture_size[::-1]


def test_load_warnings_are_kept_and_a_write_asks_before_dropping_what_the_file_had(tmp_path):
    """Finding 2: a misspelt key of the loaded file was dropped by Save without a word. The state
    carries the warnings, Save and Export answer 409 until the page confirms (drop_ignored), and
    the file is written one handle per line (as samples/astronaut_handles.json)."""
    path = tmp_path / "h.json"
    loaded = {"version": 1, "points": PINS + [{"from": [130, 60], "to": [200, 35], "angel": 30}], "colour": "red"}
    path.write_text(json.dumps(loaded))
    session = EditorSession(Settings("deform"), IMAGE, MASK, str(path), str(tmp_path / "out.png"), loaded)
    assert any("'colour'" in w for w in session.state()["warnings"])
    assert any("points[2].angel" in w for w in session.state()["warnings"])
    with served(session) as server:
        body = {"handles": session.state()["handles"]}
        for route in ("save", "export"):
            status, answer = _post(server, route, body)
            assert status == 409 and "angel" in answer["error"] and str(path) in answer["error"], answer
            assert len(answer["confirm"]) == 2 and json.loads(path.read_text()) == loaded
        assert not (tmp_path / "out.png").exists()
        status, answer = _post(server, "save", {**body, "drop_ignored": True})
        assert status == 200 and answer["saved"] == str(path)
        assert _post(server, "save", body)[0] == 200                  # confirmed once: the file is the editor's now
    lines = path.read_text().splitlines()
    assert [json.loads(line.rstrip(",")) for line in lines[3:6]] == body["handles"]["points"]
    assert json.loads(path.read_text()) == body["handles"]


SMALL = {"version": 1, "points": [{"from": [5, 5], "to": [5, 5]}, {"from": [100, 100], "to": [104, 98]}]}


def test_ctrl_c_during_an_export_puts_its_files_back_and_the_export_writes_nothing_more(tmp_path, monkeypatch):
    """Finding 3: Ctrl-C while an Export ran left its new handles file beside the old image.
    The handles are written after the image; abandon() puts every file back; the Export, when it
    comes back from the warp, writes no handles and restores what it wrote."""
    image, mask = small_astronaut(tmp_path)
    out, handles = tmp_path / "out.png", tmp_path / "out.handles.json"
    out.write_bytes(b"OLD IMAGE")
    handles.write_bytes(b"OLD HANDLES")
    session = EditorSession(Settings("deform"), image, mask, None, str(out))
    warping, release, real = threading.Event(), threading.Event(), editor_session.warp_file

    def slow(*args, **kwargs):
        summary = real(*args, **kwargs)            # the new image is written ...
        warping.set()
        release.wait(10)                           # ... and Ctrl-C comes before the handles are
        return summary

    monkeypatch.setattr(editor_session, "warp_file", slow)
    errors = []
    thread = threading.Thread(target=lambda: _catch(errors, session.export, {"handles": SMALL}))
    thread.start()
    assert warping.wait(60) and out.read_bytes() != b"OLD IMAGE"
    assert session.abandon() == str(out)
    assert out.read_bytes() == b"OLD IMAGE" and handles.read_bytes() == b"OLD HANDLES"
    release.set()
    thread.join(30)
    assert errors and "abandoned" in str(errors[0])
    assert out.read_bytes() == b"OLD IMAGE" and handles.read_bytes() == b"OLD HANDLES"
    assert EditorSession(Settings("deform"), image, mask, None, str(out)).abandon() is None   # none running


def _catch(errors, call, *args):
    try:
        call(*args)
    except Exception as err:  # noqa: BLE001  (the test reads it)
        errors.append(err)


def test_serve_prints_load_warnings_and_ctrl_c_during_an_export_exits_130(capsys):
    """Findings 2 and 3 on the terminal: what loading said is printed; Ctrl-C with an Export
    running says it was abandoned and exits 130, not 'editor stopped' and 0."""
    import click

    from featurewarp_cli.cli.edit import serve

    class Session:
        def __init__(self, running):
            self.running = running

        def state(self):
            return {"warnings": ["handles: ignoring the key 'colour' (unknown to version 1)"]}

        def abandon(self):
            return "out.png" if self.running else None

    class Server:
        url = "http://127.0.0.1:1/?token=x"

        def __init__(self, running):
            self.session = Session(running)

        def serve_forever(self, poll_interval):
            raise KeyboardInterrupt

        def server_close(self):
            pass

    serve(Server(False), quiet=False, no_browser=True)
    err = capsys.readouterr().err
    assert "featurewarp: warning: handles: ignoring the key 'colour'" in err and "editor stopped" in err
    with pytest.raises(click.exceptions.Exit) as stopped:
        serve(Server(True), quiet=True, no_browser=True)
    assert stopped.value.exit_code == 130
    assert "export of out.png abandoned" in capsys.readouterr().err


def test_a_write_error_names_the_file_not_its_temporary(tmp_path):
    """Finding 8: 'No such file or directory: .../gone/.featurewarp-46qou5f0.tmp'. Save and
    Export name the file they could not write, and why."""
    import shutil

    image, mask = small_astronaut(tmp_path)
    (tmp_path / "gone").mkdir()
    handles, out = tmp_path / "gone" / "h.json", tmp_path / "gone" / "out.png"
    session = EditorSession(Settings("deform"), image, mask, str(handles), str(out))
    shutil.rmtree(tmp_path / "gone")
    with served(session) as server:
        saved = _post(server, "save", {"handles": SMALL})
        exported = _post(server, "export", {"handles": SMALL})
    assert saved == (500, {"error": f"cannot write {handles}: the folder {tmp_path / 'gone'}/ no longer exists"})
    assert exported[0] in (400, 500) and str(tmp_path / "gone") in exported[1]["error"], exported
    assert ".tmp" not in exported[1]["error"]


def test_the_printed_command_keeps_max_memory_and_versions_tell_pages_what_another_changed(tmp_path):
    """Finding 10: --max-memory was left out of the printed command. Finding 4: a density or a
    mask set by one page shows in every later answer's versions (the other page reloads)."""
    assert options_given(Settings("deform", max_memory=300 * 2**20)) == ["--max-memory", str(300 * 2**20)]
    image, mask = small_astronaut(tmp_path)
    session = EditorSession(Settings("deform"), image, mask, None, None)
    assert session.state()["versions"] == {"grid": 0, "mask": 0}
    session.set_density({"density": "fewer"})
    assert session.solve({"handles": SMALL})[0]["versions"] == {"grid": 1, "mask": 0}
    painted = "data:image/png;base64," + base64.b64encode(session.mask_png).decode()
    assert session.set_mask({"png": painted})["version"] == 1
    assert session.state()["versions"] == {"grid": 1, "mask": 1}


def test_a_stroke_changes_the_mask_only_near_it_when_the_texture_is_smaller(tmp_path):
    """Nit: one stroke on an image wider than the texture resampled the whole mask (88 pixels
    changed far from a 5 px stroke on 8000 x 400). Only pixels under changed texels change."""
    width, height = 6000, 60
    rng = np.random.default_rng(3)
    mask = (rng.random((height // 4, width // 4)) > 0.5).astype(np.uint8) * 255
    mask = cv2.resize(mask, (width, height), interpolation=cv2.INTER_NEAREST)      # detail finer than a texel
    cv2.imwrite(str(tmp_path / "wide.png"), np.full((height, width, 3), 128, np.uint8))
    cv2.imwrite(str(tmp_path / "wide_mask.png"), mask)
    session = EditorSession(Settings("deform"), str(tmp_path / "wide.png"), str(tmp_path / "wide_mask.png"), None, None)
    painted = session.mask_texture.copy()
    assert painted.shape[1] == 4096
    painted[10:20, 100:110] = 255                                       # a stroke near the left end
    session.set_mask({"png": "data:image/png;base64," + base64.b64encode(cv2.imencode(".png", painted)[1]).decode()})
    changed = np.nonzero((session.feature_mask != (mask >= 128)).any(axis=0))[0]
    assert len(changed) and changed.min() >= 100 * width / 4096 - 4 and changed.max() <= 110 * width / 4096 + 4


def test_a_bad_handles_file_is_named_in_the_error(tmp_path):
    """Nit: 'Invalid value for '--handles': points[0].to: ...' did not say which file."""
    from click.testing import CliRunner

    from featurewarp_cli.cli.main import cli

    bad = tmp_path / "bad.json"
    bad.write_text('{"version": 1, "points": [{"from": [1, 2], "to": [3]}, {"from": [5, 5], "to": [5, 5]}]}')
    result = CliRunner().invoke(cli, ["edit", IMAGE, "--handles", str(bad), "--no-browser"])
    assert result.exit_code == 2 and f"{bad}: points[0].to" in result.output, result.output


def test_the_editor_names_the_handles_file_in_its_load_warnings(tmp_path):
    """The notes on a loaded handles file's unknown keys said "handles: ignoring ...", where
    deform names the file (smoke trial nit)."""
    path = str(tmp_path / "h.json")
    data = {"version": 1, "colour": "red", "points": [{"from": [60, 470], "to": [60, 470]},
                                                     {"from": [450, 470], "to": [450, 470]}]}
    session = EditorSession(Settings("deform"), IMAGE, MASK, path, None, data)
    assert f"{path}: ignoring the key 'colour' (unknown to version 1)" in session.state()["warnings"]


def test_export_reports_every_warning_deform_prints(tmp_path, monkeypatch):
    """Export's answer carried only the first three of the run's warnings: a fourth feature not
    kept, a crease, an unconverged rigid map that deform prints were not in the page's notice."""
    said = [f"feature {i} not kept" for i in range(4)] + ["the result crushes the image into a crease"]

    def warp_file(settings, input, output, mask, also_read=()):
        with open(output, "wb") as file:
            file.write(b"image")
        return {"seconds": 0.0, "warnings": list(said)}

    monkeypatch.setattr(editor_session, "warp_file", warp_file)
    session = EditorSession(Settings("deform"), IMAGE, MASK, None, str(tmp_path / "out.png"))
    answer = session.export(request(0))
    assert answer["warnings"] == said


def test_the_status_line_says_first_that_the_handles_ask_for_a_fold(session):
    """The page shows the first warning: for two handles dragged across each other it was the
    preview's "the features are eased ... Export solves them in full" beside "folds 0", and
    Export then refused the result as laying the image over itself. The count of features kept
    is marked provisional there (the preview's: Export's differed)."""
    swap = {"version": 1, "points": PINS + [{"from": [130, 60], "to": [400, 120]},
                                            {"from": [400, 120], "to": [130, 60]}]}
    status, _ = session.solve({"handles": swap})
    assert status["folds"] == 0 and status["provisional"] is True
    assert status["warnings"][0].startswith("the handles ask for a fold"), status["warnings"]
    status, _ = session.solve({"handles": {"version": 1, "points": PINS}})
    assert status["provisional"] is False
