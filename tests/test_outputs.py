"""Where outputs go (issues 13 and 15): through links, into FIFOs and devices, to stdout; all of
a command's outputs or none; nothing left behind by SIGTERM or SIGKILL; batch workers die with
their parent."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from featurewarp_cli.cli.main import cli
from featurewarp_cli.io import write

CLI = [sys.executable, "-m", "featurewarp_cli"]


@pytest.fixture
def picture(tmp_path) -> Path:
    path = tmp_path / "in" / "picture.png"
    path.parent.mkdir()
    cv2.imwrite(str(path), np.random.default_rng(0).integers(0, 255, (120, 160, 3), np.uint8))
    return path


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def test_a_symlinked_output_stays_a_link_and_its_target_gets_the_image(picture, tmp_path):
    target, link = tmp_path / "target.png", tmp_path / "link.png"
    link.symlink_to(target)
    assert invoke("warp", "stretch", picture, link, "--sx", "1.5").exit_code == 0
    assert link.is_symlink() and cv2.imread(str(target)).shape == (120, 240, 3)


def test_a_fifo_output_delivers_the_whole_image(picture, tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    received = []
    reader = threading.Thread(target=lambda: received.append(Path(fifo).read_bytes()))
    reader.start()
    run = subprocess.run([*CLI, "warp", "stretch", str(picture), f"png:{fifo}", "--sx", "1.5"], timeout=60)
    reader.join(10)
    assert run.returncode == 0 and fifo.exists() and not fifo.is_file()
    assert cv2.imdecode(np.frombuffer(received[0], np.uint8), cv2.IMREAD_COLOR).shape == (120, 240, 3)


@pytest.mark.parametrize("report", ["-", "/dev/stdout"])
def test_report_to_stdout(picture, tmp_path, report):
    """--report - (or /dev/stdout, which stays a symlink) prints the JSON on stdout."""
    run = subprocess.run([*CLI, "warp", "stretch", str(picture), str(tmp_path / "o.png"), "--report", report],
                         capture_output=True, timeout=60)
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout)["preset"] == "stretch"
    assert os.path.islink("/dev/stdout")


def test_two_outputs_on_stdout_are_refused(picture):
    run = invoke("warp", "stretch", picture, "png:-", "--report", "-")
    assert run.exit_code == 2 and "stdout" in run.output


def test_dev_stdout_and_dev_stderr_are_written_where_the_shell_points_them(picture, tmp_path):
    """/dev/stdout and /dev/stderr were opened anew and the file the shell redirected them to was
    replaced: ``>> log`` lost the log. They are this process's descriptors, written as they
    stand; and '-' with /dev/stdout (one stream) is refused as two stdouts are."""
    log, errors = tmp_path / "log.bin", tmp_path / "err.log"
    log.write_bytes(b"earlier line\n")
    errors.write_bytes(b"earlier line\n")
    command = " ".join([*CLI, "warp", "stretch", str(picture), "/dev/stdout", "--format", "png",
                        "--report", "/dev/stderr"])
    run = subprocess.run(f"{command} >> {log} 2>> {errors}", shell=True, timeout=60)
    assert run.returncode == 0
    assert log.read_bytes().startswith(b"earlier line\n\x89PNG")
    assert errors.read_bytes().startswith(b"earlier line\n{") and b'"preset": "stretch"' in errors.read_bytes()
    run = invoke("warp", "stretch", picture, "/dev/stdout", "--format", "png", "--report", "-")
    assert run.exit_code == 2 and "only one output can go to stdout" in run.output


@pytest.mark.parametrize("option", ["--report", "--save-grid"])
def test_an_output_naming_an_input_is_refused(picture, option):
    before = picture.read_bytes()
    run = invoke("warp", "stretch", picture, picture.with_name("o.png"), option, picture)
    assert run.exit_code == 2 and "INPUT" in run.output and "overwritten" in run.output
    assert picture.read_bytes() == before and not picture.with_name("o.png").exists()


def test_output_may_be_input(picture):
    assert invoke("warp", "stretch", picture, picture, "--sx", "1.5").exit_code == 0
    assert cv2.imread(str(picture)).shape == (120, 240, 3)


def test_a_failed_report_leaves_an_existing_output_as_it_was(picture, tmp_path, monkeypatch):
    output = tmp_path / "o.png"
    output.write_bytes(b"precious")
    staging = write._stage_file

    def full_disk(path, target, data, named=False):
        if path.endswith(".json"):
            raise OSError(28, "No space left on device", path)
        return staging(path, target, data, named)

    monkeypatch.setattr(write, "_stage_file", full_disk)
    run = invoke("warp", "stretch", picture, output, "--report", tmp_path / "r.json", "--save-grid",
                 tmp_path / "g.npz")
    assert run.exit_code == 1 and "No space left on device" in run.output
    assert output.read_bytes() == b"precious"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in", "o.png"]


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGKILL])
def test_a_signal_during_the_write_leaves_no_file(picture, tmp_path, signum):
    """Killed while its outputs wait to be put in place: the folder is as it was."""
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    env = {**os.environ, write.STAGE_DELAY_VARIABLE: "30"}
    process = subprocess.Popen([*CLI, "warp", "stretch", str(picture), str(out_dir / "o.png"), "--report",
                                str(out_dir / "r.json")], env=env, stderr=subprocess.PIPE)
    deadline = time.time() + 60
    while time.time() < deadline and not _has_open_tmpfile(process.pid):
        time.sleep(0.05)
    time.sleep(0.2)
    process.send_signal(signum)
    process.wait(10)
    assert process.returncode != 0
    assert list(out_dir.iterdir()) == []


def _has_open_tmpfile(pid: int) -> bool:
    """Whether ``pid`` holds an unnamed file (O_TMPFILE) or a featurewarp temporary file open."""
    try:
        links = [os.readlink(f"/proc/{pid}/fd/{fd}") for fd in os.listdir(f"/proc/{pid}/fd")]
    except OSError:
        return False
    return any("(deleted)" in link or write.TEMP_PREFIX in link for link in links)


def _children(pid: int) -> list[int]:
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                fields = Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                out.append(int(entry))
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.slow
def test_batch_workers_die_with_their_parent(picture, tmp_path):
    """SIGTERM to a `batch --jobs 2` parent: no worker outlives it by 2 s, no file is left."""
    for k in range(3):
        (picture.parent / f"copy{k}.png").write_bytes(picture.read_bytes())
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    env = {**os.environ, write.STAGE_DELAY_VARIABLE: "30"}
    process = subprocess.Popen([*CLI, "batch", "stretch", *map(str, sorted(picture.parent.iterdir())),
                                "--out-dir", str(out_dir), "--jobs", "2", "--sx", "1.5"], env=env,
                               stderr=subprocess.PIPE)
    deadline = time.time() + 60
    workers = []
    while time.time() < deadline:
        workers = [w for w in _children(process.pid) if _has_open_tmpfile(w)]
        if workers:
            break
        time.sleep(0.1)
    assert workers, "no worker reached its write"
    everyone = _children(process.pid)
    process.send_signal(signal.SIGTERM)
    process.wait(10)
    deadline = time.monotonic() + 2.0                  # each worker gone within 2 s (asked every 50 ms)
    while [pid for pid in everyone if _alive(pid)] and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not [pid for pid in everyone if _alive(pid)]
    assert list(out_dir.iterdir()) == []


def test_batch_refuses_to_write_over_another_jobs_input(tmp_path):
    folder = tmp_path / "pics"
    folder.mkdir()
    for name in ("a.png", "a_x.png"):
        cv2.imwrite(str(folder / name), np.zeros((20, 20, 3), np.uint8))
    run = invoke("batch", "stretch", folder / "a.png", folder / "a_x.png", "--out-dir", folder, "--suffix", "_x",
                 "--mask-pattern", "none_{stem}.png")
    assert run.exit_code == 2 and "also reads" in run.output


def _waits_on_a_pipe(pid: int) -> bool:
    """Whether process ``pid`` sleeps in a write to a full pipe (False where the kernel does not say)."""
    try:
        return Path(f"/proc/{pid}/wchan").read_text().endswith("pipe_write")
    except OSError:
        return False


def test_a_short_write_to_an_unbuffered_stdout_is_finished_or_is_an_error(picture, tmp_path):
    """With ``PYTHONUNBUFFERED`` stdout is a raw file: a write may take part of the bytes (a pipe,
    a nearly full disk). The rest is written; where the pipe is closed early that is exit 1 with
    one line, not exit 0 with a cut-short image."""
    args = [sys.executable, "-m", "featurewarp_cli", "warp", "stretch", str(picture), "-", "--sx", "2"]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    whole = subprocess.run(args, capture_output=True, env=env, check=True).stdout
    assert cv2.imdecode(np.frombuffer(whole, np.uint8), cv2.IMREAD_UNCHANGED).shape[1] == 2 * 160
    reader = "import os; os.read(0, 10); os.close(0)"
    process = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    subprocess.run([sys.executable, "-c", reader], stdin=process.stdout, check=True)
    deadline = time.monotonic() + 2.0                # until it waits on the full pipe, mid-image (2 s at most)
    while process.poll() is None and time.monotonic() < deadline and not _waits_on_a_pipe(process.pid):
        time.sleep(0.01)
    process.stdout.close()
    assert process.wait(timeout=60) == 1
    assert process.stderr.read().decode().strip().endswith("cannot write stdout: Broken pipe")

    class Partial:                                   # a raw stream that takes 5 bytes a call
        def __init__(self):
            self.data = b""

        def write(self, view):
            self.data += bytes(view[:5])
            return min(5, len(view))

        def flush(self):
            pass

    stream = Partial()
    write._write_stream(stream, b"0123456789abc")
    assert stream.data == b"0123456789abc"


def test_stdout_takes_the_input_format(picture, tmp_path):
    """'-' as OUTPUT without --format: the input's own format (a JPEG gives JPEG bytes)."""
    jpeg = tmp_path / "p.jpg"
    cv2.imwrite(str(jpeg), cv2.imread(str(picture)))
    for source, magic in ((picture, b"\x89PNG"), (jpeg, b"\xff\xd8")):
        run = subprocess.run([*CLI, "warp", "stretch", str(source), "-", "--sx", "1.2"], capture_output=True,
                             timeout=60)
        assert run.returncode == 0 and run.stdout.startswith(magic)


def _tagged_jpeg(path: Path, orientation: int = 1) -> bytes:
    """A JPEG with an ICC profile (Pillow's sRGB, as a stand-in for Adobe RGB) and EXIF."""
    from PIL import Image, ImageCms

    profile = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()
    exif = Image.Exif()
    exif[0x0112] = orientation
    exif[0x010F] = "TestMaker"
    pixels = np.random.default_rng(2).integers(0, 255, (60, 80, 3), np.uint8)
    Image.fromarray(pixels).save(path, quality=90, icc_profile=profile, exif=exif.tobytes())
    return profile


def test_icc_and_exif_are_kept_and_strip_drops_them(tmp_path):
    """The ICC profile survives warp (so colours do not shift in viewers), EXIF too with its
    orientation reset to 1 (the pixels are turned already); --strip drops both."""
    from PIL import Image

    source = tmp_path / "tagged.jpg"
    profile = _tagged_jpeg(source, orientation=6)
    for suffix in ("jpg", "png", "webp", "tiff"):
        out = tmp_path / f"o.{suffix}"
        assert invoke("warp", "swirl", source, out, "--angle", "60").exit_code == 0
        with Image.open(out) as image:
            assert image.info.get("icc_profile") == profile, suffix
            assert image.size == (60, 80)                     # turned upright once, not twice
            if suffix in ("jpg", "webp"):
                exif = image.getexif()
                assert exif.get(0x0112) == 1 and exif.get(0x010F) == "TestMaker"
    stripped = tmp_path / "s.jpg"
    assert invoke("warp", "swirl", source, stripped, "--angle", "60", "--strip").exit_code == 0
    with Image.open(stripped) as image:
        assert "icc_profile" not in image.info and not len(image.getexif())


def test_descriptor_paths_are_ascii_numbers_of_this_process():
    assert write.descriptor_of("/dev/stdout") == 1 and write.descriptor_of("/dev/stderr") == 2
    assert write.descriptor_of("/dev/fd/5") == 5 and write.descriptor_of("/proc/self/fd/7") == 7
    assert write.descriptor_of(f"/proc/{os.getpid()}/fd/3") == 3 and write.descriptor_of("-") == 1
    for other in ("/dev/fd/\u0661", "/dev/fd/\u00b2", "/dev/fd/99999999999999999999", "/proc/1/fd/1", "/dev/fd/01",
                  "/dev/fd/", "out.png", "/dev/null"):
        assert write.descriptor_of(other) is None, other


@pytest.mark.parametrize("target", ["/dev/fd/N", "-", "/dev/fd/1500"])
def test_an_inherited_non_blocking_descriptor_is_written_whole(tmp_path, monkeypatch, target):
    """A parent may leave stdout non-blocking: the write waited for nothing and failed after
    64 KiB with EAGAIN when the reader was slow ('-' too; and select() refused descriptors
    from 1024 on)."""
    import fcntl
    import io
    import resource

    reading, writing = os.pipe()
    if target == "/dev/fd/1500":
        soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
        if max(soft, hard if hard != resource.RLIM_INFINITY else 4096) <= 1500:
            pytest.skip("no descriptor 1500 allowed here")
        resource.setrlimit(resource.RLIMIT_NOFILE, (max(soft, 1501), hard))
        os.dup2(writing, 1500)
        os.close(writing)
        writing = 1500
    fcntl.fcntl(writing, fcntl.F_SETFL, fcntl.fcntl(writing, fcntl.F_GETFL) | os.O_NONBLOCK)
    if target == "-":
        monkeypatch.setattr(sys, "stdout", io.TextIOWrapper(io.BufferedWriter(io.FileIO(writing, "w", closefd=False))))
    data, got = os.urandom(1 << 20), []

    def reader():
        time.sleep(0.3)
        while chunk := os.read(reading, 1 << 16):
            got.append(chunk)

    thread = threading.Thread(target=reader)
    thread.start()
    try:
        write.commit([write.stage(target.replace("N", str(writing)), data)])
    finally:
        os.close(writing)
        thread.join()
        os.close(reading)
        if target == "/dev/fd/1500":
            resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
    assert b"".join(got) == data


def test_many_outputs_wait_in_closed_files(tmp_path, monkeypatch):
    """Each staged output held an open descriptor until the commit: an 1100-frame sequence ran out
    of them (ulimit -n 1024) after every frame was made."""
    counts = []
    commit = write.commit
    monkeypatch.setattr(write, "commit", lambda staged: (counts.append(len(os.listdir("/proc/self/fd"))),
                                                         commit(staged)))
    before = len(os.listdir("/proc/self/fd"))
    write.write_outputs([(str(tmp_path / f"f{k}.png"), b"x" * k) for k in range(write.OPEN_STAGED + 20)])
    assert counts[0] <= before + 2 and len(os.listdir(tmp_path)) == write.OPEN_STAGED + 20
    assert (tmp_path / "f7.png").read_bytes() == b"x" * 7


def test_an_exif_block_larger_than_a_jpeg_holds_is_left_out_with_a_warning(tmp_path):
    """A PNG's 70 kB EXIF failed the whole run after the solve when written as JPEG ("EXIF data
    is too long"): it is left out, the warning says so, and PNG keeps it."""
    from PIL import Image

    exif = Image.Exif()
    exif[0x010E] = "A" * 70000
    source = tmp_path / "big-exif.png"
    Image.fromarray(np.random.default_rng(4).integers(0, 255, (40, 60, 3), np.uint8)).save(source, exif=exif.tobytes())
    run = invoke("warp", "swirl", source, tmp_path / "o.jpg", "--angle", "60")
    assert run.exit_code == 0 and "is more than a JPEG holds" in run.output and (tmp_path / "o.jpg").exists()
    assert invoke("warp", "swirl", source, tmp_path / "o.png", "--angle", "60").exit_code == 0
    with Image.open(tmp_path / "o.png") as image:
        assert len(image.getexif()[0x010E]) == 70000
    run = invoke("warp", "swirl", source, tmp_path / "s.jpg", "--angle", "60", "--strict")
    assert run.exit_code == 1 and "JPEG holds" in run.output and not (tmp_path / "s.jpg").exists()


def test_quality_sets_the_jpeg_tables_and_makes_webp_lossy(tmp_path):
    """--quality 80: the JPEG's quantization tables are libjpeg's for 80 (what identify's %Q
    reads back) and the file is smaller; WebP becomes lossy."""
    from PIL import Image

    source = tmp_path / "in.png"
    cv2.imwrite(str(source), np.random.default_rng(3).integers(0, 255, (60, 80, 3), np.uint8))
    default, q80 = tmp_path / "d.jpg", tmp_path / "q80.jpg"
    assert invoke("warp", "swirl", source, default, "--angle", "60").exit_code == 0
    assert invoke("warp", "swirl", source, q80, "--angle", "60", "--quality", "80").exit_code == 0
    reference = tmp_path / "ref.jpg"
    cv2.imwrite(str(reference), cv2.imread(str(source)), [cv2.IMWRITE_JPEG_QUALITY, 80])
    with Image.open(q80) as ours, Image.open(reference) as theirs:
        assert ours.quantization == theirs.quantization
    assert q80.stat().st_size < default.stat().st_size
    lossless, lossy = tmp_path / "l.webp", tmp_path / "q.webp"
    assert invoke("warp", "swirl", source, lossless, "--angle", "60").exit_code == 0
    assert invoke("warp", "swirl", source, lossy, "--angle", "60", "--quality", "50").exit_code == 0
    assert lossy.stat().st_size < lossless.stat().st_size / 2
    assert invoke("warp", "swirl", source, lossy, "--quality", "101").exit_code == 2


@pytest.mark.parametrize("text,expected", [
    ("skyblue", (135, 206, 235)), ("#f80", (255, 136, 0)), ("#ff000080", (255, 0, 0, 128)),
    ("rgba(255, 0, 0, 0.5)", (255, 0, 0, 128)), ("rgba(255,0,0,50%)", (255, 0, 0, 128)),
    ("rgba(0, 0, 255, 1)", (0, 0, 255)), ("#00ff00ff", (0, 255, 0)), ("none", None)])
def test_colour_forms(text, expected):
    from featurewarp_cli.io.colours import parse_colour

    assert parse_colour(text, alpha=True) == expected


@pytest.mark.parametrize("text", ["rgb(300, 0, 0)", "rgba(1, 2, 3, 1.5)", "#12345", "blurple"])
def test_bad_colours_are_refused(picture, text):
    run = invoke("warp", "arc", picture, picture.with_name("o.png"), "--background", text)
    assert run.exit_code == 2 and "--background" in run.output


def test_a_translucent_background(picture, tmp_path):
    """#ff000080: uncovered pixels of a PNG are red at alpha 128; a JPEG gets it over white."""
    png, jpg = tmp_path / "o.png", tmp_path / "o.jpg"
    assert invoke("warp", "arc", picture, png, "--angle", "150", "--background", "#ff000080").exit_code == 0
    assert tuple(cv2.imread(str(png), cv2.IMREAD_UNCHANGED)[0, 0]) == (0, 0, 255, 128)
    assert invoke("warp", "arc", picture, jpg, "--angle", "150", "--background", "rgba(255,0,0,0.5)").exit_code == 0
    b, g, r = cv2.imread(str(jpg))[0, 0].astype(int)
    assert r > 240 and abs(g - 128) < 6 and abs(b - 128) < 6


def test_save_grid_as_obj_loads_in_trimesh(picture, tmp_path):
    """--save-grid x.obj: a Wavefront OBJ with as many vertices and faces as the .npz holds,
    texture coordinates in [0, 1] (issue 14)."""
    import trimesh

    obj, npz = tmp_path / "mesh.obj", tmp_path / "mesh.npz"
    mask = tmp_path / "mask.png"
    cv2.imwrite(str(mask), (np.indices((120, 160)).sum(0) % 40 < 8).astype(np.uint8) * 255)
    for grid in (obj, npz):
        run = invoke("warp", "arc", picture, tmp_path / f"{grid.stem}-{grid.suffix[1:]}.png", "-m", mask,
                     "--angle", "120", "--save-grid", grid)
        assert run.exit_code == 0, run.output
    arrays = np.load(npz)
    loaded = trimesh.load(obj, process=False, maintain_order=True)
    assert len(loaded.vertices) == len(arrays["target"]) and len(loaded.faces) == len(arrays["triangles"])
    np.testing.assert_allclose(loaded.vertices[:, :2], arrays["target"], atol=1e-5)
    np.testing.assert_array_equal(loaded.faces, arrays["triangles"])
    uv = loaded.visual.uv
    assert uv.min() >= 0 and uv.max() <= 1


def test_a_gray_image_under_a_colour_background_comes_out_in_colour(tmp_path):
    """A gray input under ``--background '#f00'`` had its red fill written as its luma (76)."""
    gray = np.random.default_rng(4).integers(0, 255, (60, 80), np.uint8)
    cv2.imwrite(str(tmp_path / "g.png"), gray)
    for colour, shape, corner in (("#f00", (80, 60, 3), [0, 0, 255]), ("#808080", (80, 60), 128)):
        run = invoke("warp", "arc", tmp_path / "g.png", tmp_path / "o.png", "--background", colour)
        assert run.exit_code == 0, run.output
        out = cv2.imread(str(tmp_path / "o.png"), cv2.IMREAD_UNCHANGED)
        assert out.shape[:2] != (60, 80) and out.ndim == len(shape) and np.array_equal(out[0, 0], corner)


@pytest.mark.parametrize("name, channels, bits, gray", [("o.jpg", 3, 8, False), ("o.bmp", 3, 8, False),
                                                        ("o.png", 4, 16, False), ("o.tif", 4, 16, False),
                                                        ("o.webp", 3, 8, True), ("o.gif", 3, 8, True)])
def test_the_report_describes_the_output_as_its_format_stores_it(tmp_path, name, channels, bits, gray):
    """A 16-bit result written as JPEG was reported as 16-bit, an RGBA one as a 4-channel BMP;
    WebP and GIF have no gray form."""
    image = (np.random.default_rng(5).integers(0, 255, (60, 80) if gray else (60, 80, 3)) * 257).astype(np.uint16)
    cv2.imwrite(str(tmp_path / "in.png"), image)
    extra = ["--background", "white"] if gray else []
    run = invoke("warp", "arc", tmp_path / "in.png", tmp_path / name, "--report", tmp_path / "r.json", *extra)
    assert run.exit_code == 0, run.output
    output = json.loads((tmp_path / "r.json").read_text())["output"]
    written = cv2.imread(str(tmp_path / name), cv2.IMREAD_UNCHANGED)
    assert (output["channels"], output["bits"]) == (channels, bits) == (written.shape[2], 8 * written.itemsize)


def test_the_report_gives_a_transparent_gif_its_alpha(tmp_path):
    """A GIF written with --background transparent keeps its alpha (cut at half) but the report
    said 3 channels, as for a GIF laid over white."""
    from PIL import Image

    cv2.imwrite(str(tmp_path / "in.png"), np.random.default_rng(5).integers(0, 255, (60, 80, 3)).astype(np.uint8))
    for background, channels in (("transparent", 4), ("white", 3)):
        run = invoke("warp", "arc", tmp_path / "in.png", tmp_path / "o.gif", "--report", tmp_path / "r.json",
                     "--background", background)
        assert run.exit_code == 0, run.output
        assert json.loads((tmp_path / "r.json").read_text())["output"]["channels"] == channels
        with Image.open(tmp_path / "o.gif") as gif:
            assert ("transparency" in gif.info) == (channels == 4)


def test_a_transparent_input_laid_over_the_background_leaves_no_seam_at_the_warps_edge(tmp_path):
    """The silhouette's partly covered pixels were blended with the fill by coverage alone, not by
    their own alpha: the hidden colour under alpha 0 showed as a gray line along the edge (BMP, JPEG)."""
    image = np.zeros((60, 80, 4), np.uint8)              # black, wholly transparent
    cv2.imwrite(str(tmp_path / "in.png"), image)
    run = invoke("warp", "arc", tmp_path / "in.png", tmp_path / "o.bmp", "--angle", "120")
    assert run.exit_code == 0, run.output
    assert cv2.imread(str(tmp_path / "o.bmp")).min() == 255


def test_a_gray_image_is_written_as_gif():
    """OpenCV's GIF encoder refused one channel: "cannot encode the result as gif"."""
    from featurewarp_cli.io.encode import encode_image

    gray = np.random.default_rng(6).integers(0, 255, (30, 40), np.uint8)
    decoded = cv2.imdecode(np.frombuffer(encode_image(gray, "gif"), np.uint8), cv2.IMREAD_GRAYSCALE)
    assert np.array_equal(decoded, gray)                 # 256 grays: exact


def test_a_colour_gif_takes_an_adaptive_palette():
    """OpenCV's GIF encoder took a fixed palette: a smooth photo came back 20 levels off on
    average, with bright yellow bands where it was gray."""
    from featurewarp_cli.io.encode import encode_image

    y, x = np.mgrid[0:64, 0:96]
    image = np.dstack([150 + x // 3, 140 + y // 3, 130 + (x + y) // 6]).astype(np.uint8)   # grays, BGR
    decoded = cv2.imdecode(np.frombuffer(encode_image(image, "gif"), np.uint8), cv2.IMREAD_COLOR)
    error = np.abs(decoded.astype(int) - image).max(axis=2)
    assert error.mean() < 3 and error.max() < 16


def test_save_grid_names_one_of_the_two_forms_it_writes(picture, tmp_path):
    """Any other name silently got an .npz archive."""
    run = invoke("warp", "stretch", picture, tmp_path / "o.png", "--save-grid", tmp_path / "g.txt")
    assert run.exit_code == 2 and "neither an .npz nor an .obj" in run.output
    assert list(tmp_path.glob("[og].*")) == []


def test_an_encoders_temporary_file_is_removed_by_the_signal_handlers_too(tmp_path):
    """animate's GIF/WebP/video encoders write a named temporary file: it was not known to the
    SIGINT/SIGTERM handlers, and an interrupted run left a hidden file of up to 50 MB."""
    with write.temporary_file(str(tmp_path), ".gif") as path:
        assert os.path.exists(path) and os.path.basename(path).startswith(write.TEMP_PREFIX)
        write.remove_pending()                   # what the handlers do
        assert not os.path.exists(path)
    with write.temporary_file(str(tmp_path), ".gif") as path:
        pass
    assert not os.path.exists(path) and os.listdir(tmp_path) == []


def test_a_signal_while_a_library_message_is_captured_is_still_said():
    """Decoding captures fd 2 (libpng's messages): "stopped by SIGINT" went into the capture and a
    run stopped during a decode ended with exit 130 and nothing said. A second signal during the
    handler (a double Ctrl-C) changes nothing."""
    script = ("import os, signal\n"
              "from featurewarp_cli.cli.main import stop_on_signal\n"
              "from featurewarp_cli.io import write\n"
              "from featurewarp_cli.io.capture import captured_stderr\n"
              "signal.signal(signal.SIGINT, stop_on_signal)\n"
              "removed = write.remove_pending\n"
              "def again():                      # a second signal while the handler works\n"
              "    os.kill(os.getpid(), signal.SIGINT); removed()\n"
              "write.remove_pending = again\n"
              "with captured_stderr():\n"
              "    os.kill(os.getpid(), signal.SIGINT)\n"
              "    import time; time.sleep(5)\n")
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, timeout=60)
    assert run.returncode == 130 and run.stderr.decode() == "featurewarp: stopped by SIGINT\n", run.stderr


def test_a_named_staged_file_is_pending_while_it_is_written(tmp_path, monkeypatch):
    """A sequence of more than 256 frames stages named files; Ctrl-C while one was written left it
    (it joined _PENDING only once written): the handlers must see it from its creation."""
    seen = []
    real = write._write_all

    def spy(fd, data):
        seen.append(set(write._PENDING))
        return real(fd, data)

    monkeypatch.setattr(write, "_write_all", spy)
    staged = write._stage_file(str(tmp_path / "a.png"), str(tmp_path / "a.png"), b"x", named=True)
    assert seen and staged.temp in seen[0]
    write.remove_pending()
    assert not os.path.exists(staged.temp)


def test_a_sixteen_bit_input_written_to_an_eight_bit_format_is_said(tmp_path):
    """compare and animate said their 8-bit outputs lose the input's 16 bits; warp to JPEG did not."""
    samples = (np.random.default_rng(3).random((40, 60, 3)) * 65535).astype(np.uint16)
    cv2.imwrite(str(tmp_path / "in.png"), samples)
    for name, said in (("o.jpg", "JPEG holds 8"), ("o.webp", "WebP holds 8"), ("o.png", None), ("o.tif", None)):
        run = CliRunner().invoke(cli, ["warp", "swirl", str(tmp_path / "in.png"), str(tmp_path / name)])
        assert run.exit_code == 0, run.output
        assert (f"the input has 16 bits a sample; {said} (PNG and TIFF keep 16)" in run.output if said
                else run.output == ""), (name, run.output)
    cv2.imwrite(str(tmp_path / "in8.png"), (samples >> 8).astype(np.uint8))
    assert CliRunner().invoke(cli, ["warp", "swirl", str(tmp_path / "in8.png"), str(tmp_path / "o8.jpg")]).output == ""
    strict = CliRunner().invoke(cli, ["warp", "swirl", str(tmp_path / "in.png"), str(tmp_path / "s.jpg"), "--strict"])
    assert strict.exit_code == 1 and not (tmp_path / "s.jpg").exists()
