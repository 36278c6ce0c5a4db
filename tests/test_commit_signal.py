"""A SIGINT between two files' renames left the image new and its report old (all or nothing broken)."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

SCRIPT = textwrap.dedent("""
    import os, signal, sys
    from featurewarp_cli.cli.main import stop_on_signal
    from featurewarp_cli.io import write
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, stop_on_signal)
    real = os.replace
    def replace(src, dst):              # Ctrl-C arrives just after the first file is in place
        real(src, dst)
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(100):            # the handler runs here unless the signal is held
            pass
    os.replace = replace
    write.write_outputs([(sys.argv[1], b"new image"), (sys.argv[2], b"new report")])
""")


def test_a_signal_during_commit_leaves_all_files_new_or_all_old(tmp_path):
    image, report = tmp_path / "out.png", tmp_path / "out.json"
    image.write_bytes(b"old image")
    report.write_bytes(b"old report")
    run = subprocess.run([sys.executable, "-c", SCRIPT, str(image), str(report)], cwd=ROOT,
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 130 and "stopped by SIGINT" in run.stderr
    pair = (image.read_bytes(), report.read_bytes())
    assert pair in {(b"old image", b"old report"), (b"new image", b"new report")}, pair
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json", "out.png"]
