"""Issue 15: bounded time and memory. Bombs are refused from their headers, the grid and the
images stay within the memory budget, declared ranges hold, and a folded result is an error."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from bombs import BOMBS
from one_process import run_commands
from test_cli import Run, Runner
from featurewarp_cli import FeatureWarper, load_warp
from featurewarp_cli.io import limits

run = Runner()                    # in-process (CliRunner): exit codes and messages as the console script's


def one_line_error(result: Run, code: int, *words: str) -> None:
    """Exit ``code``, one line on stderr holding ``words``, no traceback."""
    assert result.code == code, (result.code, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    for word in words:
        assert word in lines[0], lines[0]


@pytest.fixture(scope="module")
def bomb_outcomes(tmp_path_factory):
    """Every bomb as input and as mask, all in one process (its peak memory bounds each case's):
    {(name, role): (outcome, output path)}."""
    folder = tmp_path_factory.mktemp("bombs")
    small = folder / "small.png"
    cv2.imwrite(str(small), np.zeros((8, 8, 3), np.uint8))
    cases, commands = [], []
    for name, (suffix, data) in sorted(BOMBS.items()):
        bomb = folder / f"{name}{suffix}"
        bomb.write_bytes(data)
        for role in ("input", "mask"):
            source, mask = (bomb, small) if role == "input" else (small, bomb)
            out = folder / f"{name}-{role}-out.png"
            cases.append((name, role, out))
            commands.append(["warp", "stretch", source, out, "-m", mask, "--sx", "2", "--max-pixels", "1000000"])
    return {(name, role): (outcome, out) for (name, role, out), outcome in zip(cases, run_commands(commands))}


@pytest.mark.parametrize("name", sorted(BOMBS))
@pytest.mark.parametrize("role", ["input", "mask"])
def test_bombs_are_refused_fast_and_small(bomb_outcomes, name, role):
    """Every format's header bomb: refused within 1 s and 200 MB, nothing written."""
    result, out = bomb_outcomes[name, role]
    assert result.returncode == 1 and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert "--max-pixels" in result.stderr or "cannot be decoded" in result.stderr, result.stderr
    assert result.seconds < 5.0           # 1 s on an idle machine; CI machines are shared
    assert result.peak < 200 * 2**20
    assert not out.exists()


def test_explicit_cell_beyond_the_memory_budget_is_refused(tmp_path):
    """--cell is held to the budget too (it used to escape the automatic cell's node cap)."""
    image = tmp_path / "in.png"
    cv2.imwrite(str(image), np.zeros((300, 400, 3), np.uint8))
    one_line_error(run("warp", "stretch", image, tmp_path / "o.png", "--cell", "1", "--max-memory", "64M"),
                   2, "--cell 1", "--max-memory")
    one_line_error(run("warp", "stretch", image, tmp_path / "o.png", "--max-memory", "1M"), 1, "--max-memory")
    one_line_error(run("warp", "stretch", image, tmp_path / "o.png", "--max-memory", "lots"), 2, "--max-memory")
    assert list(tmp_path.iterdir()) == [image]


def test_node_budget_counts_the_images():
    assert limits.node_budget(4000, 3000, (4000, 3000), None) is None
    budget = limits.node_budget(100, 100, (200, 100), 10 * 2**20)
    assert budget == (10 * 2**20 - 100 * 100 * limits.INPUT_PIXEL_BYTES
                      - 200 * 100 * limits.OUTPUT_PIXEL_BYTES) // limits.NODE_BYTES
    with pytest.raises(limits.ImageError, match="--max-memory"):
        limits.node_budget(4000, 3000, (4000, 3000), 2**20)
    with pytest.raises(ValueError, match="--cell"):
        FeatureWarper(4000, 3000, cell=1, max_nodes=100_000)


def test_a_size_above_a_limit_never_reads_as_the_limit():
    mib = 1 << 20
    assert limits.size_text(37 * mib) == "37 MiB" and limits.size_text(900) == "900 bytes"
    assert limits.size_text(10 * mib + 5000, 10 * mib) == "10.005 MiB"
    assert limits.size_text(10 * mib + 1, 10 * mib) != limits.size_text(10 * mib)
    assert limits.size_text(37 * mib, 10 * mib) == "37 MiB"


def test_a_budget_refuses_the_automatic_grid_but_never_coarsens_it():
    """The memory budget only refuses: within it the grid (and so every pixel) is the same as
    without one; above it the solve is refused, not done on a coarser grid (issue 21: a
    result must not depend on the machine's memory)."""
    from featurewarp_cli.engine.fidelity import GridBudgetError

    warp = load_warp("swirl")(320, 240, angle=540)
    free = FeatureWarper(320, 240).solve(warp, "plain")
    needed = free.record.grid["nodes"]
    assert needed > 20_000
    within = FeatureWarper(320, 240, max_nodes=needed).solve(warp, "plain")
    np.testing.assert_array_equal(within.target, free.target)
    with pytest.raises(GridBudgetError, match="memory limit"):
        FeatureWarper(320, 240, max_nodes=20_000).solve(warp, "plain")


def test_a_grid_above_the_budget_is_a_one_line_error(tmp_path):
    image = tmp_path / "in.png"
    cv2.imwrite(str(image), np.zeros((240, 320, 3), np.uint8))
    one_line_error(run("warp", "swirl", image, tmp_path / "o.png", "--angle", "540", "--max-memory", "12M"),
                   1, "memory limit", "--max-memory")
    assert list(tmp_path.iterdir()) == [image]


def test_a_folded_result_is_an_error_unless_allowed(tmp_path):
    """A grid too coarse for the warp folds; that is exit 1 with nothing written, unless
    --allow-folds."""
    image = tmp_path / "in.png"
    cv2.imwrite(str(image), np.zeros((120, 160, 3), np.uint8))
    out = tmp_path / "o.png"
    one_line_error(run("warp", "swirl", image, out, "--angle", "540", "--cell", "16", "--mode", "plain"),
                   1, "folded triangles", "--allow-folds")
    assert not out.exists()
    allowed = run("warp", "swirl", image, out, "--angle", "540", "--cell", "16", "--mode", "plain", "--allow-folds")
    assert allowed.code == 0 and out.exists()


@pytest.mark.parametrize("option,value", [("--feature-weight", "1e8"), ("--decay", "1e6"), ("--angle", "1080")])
def test_values_beyond_the_solvable_ranges_are_refused_at_parse_time(tmp_path, option, value):
    image = tmp_path / "in.png"
    cv2.imwrite(str(image), np.zeros((40, 40, 3), np.uint8))
    one_line_error(run("warp", "swirl", image, tmp_path / "o.png", option, value), 2, option)


@pytest.mark.parametrize("size", [(1, 400), (400, 1), (3, 300)])
def test_images_too_thin_for_features_warp_without_them(size):
    """A mask on an image under 4 px thin is ignored, with a warning, and nothing folds."""
    w, h = size
    mask = np.ones((h, w), bool)
    mask[: h // 2] = False
    warper = FeatureWarper(w, h, mask)
    mesh = warper.solve(load_warp("arc")(w, h, angle=360))
    assert mesh.flips() == 0
    assert any("too thin" in line for line in mesh.record.warnings)


def test_a_compare_panel_is_held_to_the_limits_before_any_work(tmp_path):
    """--panel-width scaled the views up with no check: 12000 px across wrote a 36 MP panel
    at 385 MB with --max-memory 60M; at its old minimum (16) it gave 28 px in silence."""
    cv2.imwrite(str(tmp_path / "in.png"), np.random.default_rng(3).integers(0, 255, (60, 80, 3), np.uint8))
    base = ["compare", "swirl", str(tmp_path / "in.png"), str(tmp_path / "o.png")]
    one_line_error(run(*base, "--panel-width", "12000", "--max-memory", "60M"), 1,
                   "panel needs about", "--max-memory")
    one_line_error(run(*base, "--panel-width", "12000", "--max-pixels", "100000"), 1, "the panel", "--max-pixels")
    one_line_error(run(*base, "--panel-width", "16"), 2, "28 <= PX")
    assert not (tmp_path / "o.png").exists()
    assert run(*base, "--panel-width", "28", "-q").code == 0 and cv2.imread(str(tmp_path / "o.png")).shape[1] == 28
