"""Issue 22 item 3: every visible compromise is one warning line naming the place and the
figure: background stretched into streaks, blank canvas beyond the plain warp's, the outline
let go; ``--strict`` refuses each with nothing written, and ``compare`` says its views'."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from featurewarp_cli import FeatureWarper, load_warp
from featurewarp_cli.cli.main import cli
from featurewarp_cli.engine import canvas
from featurewarp_cli.engine.grid import Grid
from featurewarp_cli.engine.record import BLANK, OUTLINE_PX, STREAKS


def test_the_outline_goes_once_around_the_grid():
    ring = canvas.outline(5, 4)
    assert ring.size == 2 * (5 + 4) - 4 and np.unique(ring).size == ring.size
    grid = Grid.for_image(40, 30, 10)
    assert set(canvas.outline(grid.nx, grid.ny)) == set(np.flatnonzero(grid.boundary()))


def test_an_identity_mesh_leaves_nothing_blank_and_a_shifted_one_its_share():
    grid = Grid.for_image(40, 30, 5)
    nodes = grid.nodes()
    blank, plain, box = canvas.blank_shares(nodes, nodes, grid.nx, grid.ny, (40, 30))
    assert blank == plain == 0.0 and box is None
    shifted = nodes + [10.0, 0.0]                              # a quarter of the width left blank
    blank, plain, box = canvas.blank_shares(shifted, nodes, grid.nx, grid.ny, (40, 30))
    assert blank == pytest.approx(0.25) and plain == 0.0 and box == (0, 0, 9, 29)


def test_the_stretch_is_the_largest_singular_value_beyond_w():
    grid = Grid.for_image(40, 30, 5)
    nodes = grid.nodes()
    sheared = nodes @ np.array([[3.0, 0.0], [0.0, 0.5]]).T     # 3x across, half height
    stretch, where = canvas.largest_stretch(sheared, nodes, grid.triangles())
    assert stretch == pytest.approx(3.0) and where is not None
    assert canvas.largest_stretch(nodes, nodes, grid.triangles())[0] == 1.0


def test_the_outline_counts_only_leaving_w_outline_not_sliding_along_it():
    grid = Grid.for_image(40, 30, 5)
    nodes = grid.nodes()
    ring = canvas.outline(grid.nx, grid.ny)
    slid = nodes.copy()
    top = ring[1:grid.nx - 1]
    slid[top, 0] += 2.0                                         # along the straight top edge
    assert canvas.outline_departure(slid, nodes, grid.nx, grid.ny)[0] == pytest.approx(0.0)
    lifted = nodes.copy()
    lifted[top[3], 1] -= 4.0                                    # off it
    distance, where = canvas.outline_departure(lifted, nodes, grid.nx, grid.ny)
    assert distance == pytest.approx(4.0) and where == pytest.approx(tuple(lifted[top[3]]))


@pytest.fixture(scope="module")
def band_mesh():
    """A feature band across the full height under stretch --sy 2, rigid, with --boundary
    release: it keeps its height, so the canvas above and below it is left blank and the
    outline leaves W's."""
    mask = np.zeros((60, 80), bool)
    mask[:, 20:60] = True
    return FeatureWarper(80, 60, mask, boundary="release").solve(load_warp("stretch")(80, 60, sy=2), "rigid")


def test_by_default_the_outline_and_the_canvas_are_the_warps_and_the_feature_gives_way():
    """Issue 22 item 1: the same band by default: the border holds, the band stretches, and
    the warnings say that it gave way (the cat close-up left 39 % of its canvas blank)."""
    mask = np.zeros((60, 80), bool)
    mask[:, 20:60] = True
    record = FeatureWarper(80, 60, mask).solve(load_warp("stretch")(80, 60, sy=2), "rigid").record
    assert record.blank_share <= record.plain_blank_share + BLANK and record.outline_departure <= OUTLINE_PX
    assert any("cut by a border that no similarity of it can follow" in w for w in record.warnings)
    assert any("feature 0" in w and "not kept" in w for w in record.warnings)


def test_blank_canvas_and_an_outline_let_go_are_said_with_their_figures(band_mesh):
    record = band_mesh.record
    assert record.blank_share > record.plain_blank_share + BLANK
    assert record.outline_departure > OUTLINE_PX
    blank = [w for w in record.warnings if "is blank where the plain warp leaves" in w]
    outline = [w for w in record.warnings if "outline leaves the plain warp's" in w]
    assert len(blank) == 1 and f"{100 * record.blank_share:.1f} %" in blank[0]
    assert len(outline) == 1 and f"{record.outline_departure:.0f} px" in outline[0]
    x0, y0, x1, y1 = record.blank_extra_box
    assert 0 <= x0 <= x1 < 80 and 0 <= y0 <= y1 < 120


def test_the_plain_mode_and_an_easy_warp_say_nothing():
    mask = np.zeros((60, 80), bool)
    mask[20:40, 30:50] = True
    for mode in ("plain", "similarity"):
        mesh = FeatureWarper(80, 60, mask).solve(load_warp("stretch")(80, 60, sx=1.3), mode)
        assert mesh.record.warnings == [] and mesh.record.background_stretch < STREAKS


def test_compare_says_each_views_warnings_and_strict_writes_nothing(tmp_path):
    import cv2

    image = np.random.default_rng(1).integers(0, 255, (60, 80, 3), dtype=np.uint8)
    mask = np.zeros((60, 80), np.uint8)
    mask[:, 20:60] = 255
    cv2.imwrite(str(tmp_path / "in.png"), image)
    cv2.imwrite(str(tmp_path / "m.png"), mask)
    args = ["compare", "stretch", str(tmp_path / "in.png"), str(tmp_path / "panel.png"), "-m", str(tmp_path / "m.png"),
            "--sy", "2", "--boundary", "release"]
    run = CliRunner().invoke(cli, args)
    assert run.exit_code == 0, run.output
    assert "rigid view: " in run.output and "is blank where the plain warp leaves" in run.output
    strict = CliRunner().invoke(cli, args[:3] + [str(tmp_path / "strict.png")] + args[4:] + ["--strict"])
    assert strict.exit_code == 1 and "--strict: rigid view: " in strict.output       # which view, named
    assert not (tmp_path / "strict.png").exists()


def test_compare_says_a_coarse_grids_stray_once_for_all_views(tmp_path):
    """The three views share one grid: its stray from the warp is one line, for all of them."""
    import cv2

    image = np.random.default_rng(2).integers(0, 255, (96, 128, 3), dtype=np.uint8)
    mask = np.zeros((96, 128), np.uint8)
    mask[30:60, 40:80] = 255
    cv2.imwrite(str(tmp_path / "in.png"), image)
    cv2.imwrite(str(tmp_path / "m.png"), mask)
    run = CliRunner().invoke(cli, ["compare", "swirl", str(tmp_path / "in.png"), str(tmp_path / "panel.png"),
                                   "-m", str(tmp_path / "m.png"), "--angle", "90", "--cell", "32"])
    assert run.exit_code == 0, run.output
    strays = [line for line in run.output.splitlines() if "strays up to" in line]
    assert len(strays) == 1 and "all views: the given cell's grid (cell 32 px) strays up to" in strays[0]


def test_an_empty_mask_is_a_warning_in_the_report_and_under_strict_as_on_stderr(tmp_path):
    """The mask's own warning (it marks nothing: a plain warp) was said on stderr only: the report's
    ``warnings`` lacked it and --strict wrote the file."""
    import json

    import cv2

    cv2.imwrite(str(tmp_path / "in.png"), np.random.default_rng(3).integers(0, 255, (60, 80, 3), dtype=np.uint8))
    cv2.imwrite(str(tmp_path / "m.png"), np.zeros((60, 80), np.uint8))
    base = [str(tmp_path / "in.png"), "-m", str(tmp_path / "m.png")]
    run = CliRunner().invoke(cli, ["warp", "swirl", base[0], str(tmp_path / "o.png"), *base[1:],
                                   "--report", str(tmp_path / "r.json")])
    assert run.exit_code == 0 and "the mask marks no feature" in run.output
    report = json.loads((tmp_path / "r.json").read_text())
    assert any("the mask marks no feature" in line for line in report["warnings"])
    assert report["mode"] == "plain" and report["features_kept"] is None        # it said similarity, kept
    cv2.imwrite(str(tmp_path / "full.png"), np.full((60, 80), 255, np.uint8) * (np.arange(80) > 40))
    for extra, mode, kept in ((["--mode", "plain"], "plain", None), ([], "similarity", True)):
        CliRunner().invoke(cli, ["warp", "stretch", base[0], str(tmp_path / "p.png"), "-m", str(tmp_path / "full.png"),
                                 "--sx", "1.2", "--report", str(tmp_path / "p.json"), *extra])
        report = json.loads((tmp_path / "p.json").read_text())
        assert (report["mode"], report["features_kept"]) == (mode, kept)
    for command in ("warp", "compare"):
        strict = CliRunner().invoke(cli, [command, "swirl", base[0], str(tmp_path / "s.png"), *base[1:], "--strict"])
        assert strict.exit_code == 1 and "--strict: the mask marks no feature" in strict.output
        assert not (tmp_path / "s.png").exists()


def test_many_features_not_kept_are_named_ten_at_a_time():
    """A noisy mask of thousands of specks printed a line for each; the ten largest are named,
    the rest counted in one line (the report keeps each)."""
    from types import SimpleNamespace

    from featurewarp_cli.engine.record import MOST_LISTED, ComponentRecord, SolveRecord, warnings_for

    record = SolveRecord("similarity", "exact", "slide", {})
    record.components = [ComponentRecord(quads=1 + k % 7, tied=True, unpinned=False, scale=1.0, rotation_deg=0.0,
                                         distortion=0.5, anisotropy_worst=0.5, anisotropy_mean=0.2,
                                         plain_distortion=0.5, plain_anisotropy_worst=0.5, area_ratio=1.0,
                                         kept=k % 3 != 0) for k in range(60)]
    nodes = np.zeros((4, 2))
    warp = SimpleNamespace(canvas=(10, 10), width=20, height=20)
    lines = warnings_for(record, nodes, nodes, nodes, warp)
    named = [line for line in lines if line.startswith("feature ")]
    lost = [k for k, c in enumerate(record.components) if not c.kept]
    shown = [int(line.split()[1]) for line in named]
    rest = [record.components[k].quads for k in lost if k not in shown]
    assert len(named) == MOST_LISTED and min(record.components[k].quads for k in shown) >= max(rest)
    assert lines[-1] == (f"{len(rest)} smaller features not kept either ({min(rest)} to {max(rest)} quads; "
                         f"the report lists each)")


def test_one_line_per_feature_not_kept_with_every_cause_and_none_for_a_feature_still_kept():
    """Issue 22 item 3: a feature that gave way prints one line naming its figure and why; one
    that gave way but kept its shape (within KEPT) is no visible compromise and prints none."""
    from types import SimpleNamespace

    from featurewarp_cli.engine.record import KEPT, ComponentRecord, SolveRecord, warnings_for

    def component(tied, worst):
        return ComponentRecord(quads=40, tied=tied, unpinned=False, scale=1.0, rotation_deg=0.0, distortion=worst,
                               anisotropy_worst=worst, anisotropy_mean=worst / 2, plain_distortion=0.5,
                               plain_anisotropy_worst=0.5, area_ratio=1.0, kept=worst <= KEPT)

    record = SolveRecord("similarity", "exact", "fixed", {})
    record.components = [component(False, KEPT / 2), component(False, 0.3), component(True, 0.2)]
    record.guard.plain_blend, record.guard.degraded_components = 0.4, [1]
    nodes = np.zeros((4, 2))
    lines = warnings_for(record, nodes, nodes, nodes, SimpleNamespace(canvas=(10, 10), width=20, height=20))
    assert len(lines) == 2, lines
    assert lines[0].startswith("feature 1 (40 quads) not kept: worst-triangle anisotropy 0.300 (plain warp: 0.500): "
                               "cut by a border that no similarity of it can follow")
    assert "; moved towards the plain warp (blend 0.40, 0 = the plain warp)" in lines[0]
    assert lines[1] == "feature 2 (40 quads) not kept: worst-triangle anisotropy 0.200 (plain warp: 0.500)"


def test_a_grid_that_strays_from_the_warp_is_said_whether_chosen_or_the_finest_automatic_one():
    """The output follows W only as closely as its grid: a coarse ``--cell`` (20 px off under
    swirl 180) and the finest automatic grid where even it cannot follow (a full circle of a
    1-px strip: 0.8 px) are warnings with the figure; the automatic grid within 0.5 px, and
    the plain mode with it, say nothing."""
    mask = np.zeros((96, 128), bool)
    mask[30:60, 40:80] = True
    swirl = load_warp("swirl")(128, 96, angle=180)
    coarse = FeatureWarper(128, 96, mask, cell=32).solve(swirl, "similarity").record
    assert coarse.grid["pl_error_px"] > 10
    assert [line for line in coarse.warnings if "strays" in line] == [
        f"the given cell's grid (cell 32 px) strays up to {coarse.grid['pl_error_px']:.1f} px from the warp: the "
        f"output follows the warp only that closely; a finer --cell, or the automatic grid (within 0.5 px), "
        f"follows it more closely"]
    whole = FeatureWarper(128, 96, mask, cell=1000).solve(swirl, "similarity").record     # 4 nodes: W's midpoints
    assert whole.grid["nodes"] == 4 and whole.grid["pl_error_px"] > 10                   # agree (its centre, the
    assert any("strays up to" in line for line in whole.warnings)                        # border); inside, not
    preview = FeatureWarper(128, 96, mask, cell=32).solve(swirl, "similarity", quick=True).record
    assert not any("strays" in line for line in preview.warnings)      # a preview's grid is not measured
    for mode in ("similarity", "plain"):
        automatic = FeatureWarper(128, 96, mask).solve(swirl, mode).record
        assert automatic.grid["pl_error_px"] <= 0.5 and not any("strays" in line for line in automatic.warnings)
    strip = FeatureWarper(1, 300, np.zeros((300, 1), bool)).solve(load_warp("arc")(1, 300, angle=360)).record
    assert strip.grid["pl_error_px"] > 0.5
    assert any(line.startswith("the finest automatic grid") and "strays" in line for line in strip.warnings)


@pytest.mark.parametrize("cell", [7, 64])
def test_a_handles_map_followed_on_a_refinement_of_its_lattice_never_strays(cell):
    """``deform``'s W is piecewise linear on the handles' grid, and the mesh refines that
    lattice at any ``--cell``: it follows W exactly, so no cell says it strays."""
    from featurewarp_cli.engine.deform import Deformer
    from featurewarp_cli.engine.handles import Handles

    mask = np.zeros((90, 120), bool)
    mask[30:60, 40:80] = True
    handles = Handles.from_dict({"version": 1, "canvas": "input", "points": [
        {"from": [10, 10], "to": [10, 10]}, {"from": [110, 80], "to": [90, 85]}, {"from": [60, 45], "to": [70, 30]}]},
        120, 90)
    record = Deformer(120, 90, mask, cell=cell).solve(handles).record
    assert record.grid["pl_error_px"] < 1e-9 and not any("strays" in line for line in record.warnings)


def test_a_cameras_mpo_jpeg_is_one_photo_not_several_frames(tmp_path):
    """A camera stores previews after the photo (MPO): no "several frames" warning, which
    --strict would refuse; an animated GIF still gets it."""
    import io

    from PIL import Image

    photo = Image.fromarray(np.random.default_rng(7).integers(0, 255, (60, 80, 3), dtype=np.uint8))
    preview = Image.fromarray(np.zeros((15, 20, 3), np.uint8))
    photo.save(tmp_path / "cam.jpg", "MPO", save_all=True, append_images=[preview])
    run = CliRunner().invoke(cli, ["warp", "stretch", str(tmp_path / "cam.jpg"), str(tmp_path / "o.png"),
                                   "--sx", "1.2", "--strict"])
    assert run.exit_code == 0 and "several frames" not in run.output, run.output
    photo.save(tmp_path / "anim.gif", save_all=True, append_images=[preview.resize((80, 60))])
    run = CliRunner().invoke(cli, ["warp", "stretch", str(tmp_path / "anim.gif"), str(tmp_path / "g.png"), "--sx", "1.2"])
    assert run.exit_code == 0 and "several frames" in run.output


@pytest.mark.parametrize("command", [["compare", "stretch"], ["animate", "stretch"]])
def test_compare_and_animate_say_an_input_has_several_frames_and_strict_refuses_it(tmp_path, command):
    """``warp`` said the first frame of an animated input was used; ``compare`` and ``animate``
    used it silently, and their ``--strict`` wrote the file."""
    from PIL import Image

    frames = [Image.fromarray(np.full((60, 80, 3), value, np.uint8)) for value in (40, 200)]
    frames[0].save(tmp_path / "anim.gif", save_all=True, append_images=frames[1:])
    extra = ["--vary", "sx=1:1.5", "--frames", "2"] if command[0] == "animate" else ["--sx", "1.5"]
    out = tmp_path / ("o.gif" if command[0] == "animate" else "o.png")
    run = CliRunner().invoke(cli, command + [str(tmp_path / "anim.gif"), str(out)] + extra)
    assert run.exit_code == 0 and "several frames" in run.output, run.output
    out.unlink()
    run = CliRunner().invoke(cli, command + [str(tmp_path / "anim.gif"), str(out), "--strict"] + extra)
    assert run.exit_code == 1 and "several frames" in run.output and not out.exists(), run.output


def test_a_feature_is_named_by_where_it_is_as_well_as_by_its_number():
    """Warnings said "feature 0" and the report's components had no position: which region a
    warning was about could not be told. Each component's ``at`` is the mean source position of
    its nodes, and a warning names it."""
    mask = np.zeros((120, 160), bool)
    mask[20:40, 20:40] = True                    # top left, and a bar across the bottom right
    mask[90:100, 80:150] = True
    mesh = FeatureWarper(160, 120, mask).solve(load_warp("stretch")(160, 120, sx=0.3), "rigid")
    at = sorted(tuple(c.at) for c in mesh.record.components)
    assert np.allclose(at[0], (29.5, 29.5), atol=4) and np.allclose(at[1], (114.5, 94.5), atol=4)
    for k, component in enumerate(mesh.record.components):
        named = [line for line in mesh.record.warnings if line.startswith(f"feature {k} (")]
        assert component.kept or named[0].startswith(
            f"feature {k} ({component.quads} quads, around ({round(component.at[0])}, {round(component.at[1])})) not kept")
    assert not all(c.kept for c in mesh.record.components)


@pytest.mark.parametrize("preset, params, still", [
    ("stretch", {}, True),                                     # its 1 x 1 defaults
    ("swirl", {"center": (5000, 5000)}, True),                 # centred far off the image
    ("bulge", {"strength": 0.0}, True),
    ("bulge", {"strength": 0.05}, False),
])
def test_a_warp_that_moves_nothing_says_so(preset, params, still):
    """Such a warp was written silently, reported with every feature kept, and passed --strict."""
    mask = np.zeros((60, 80), bool)
    mask[20:40, 30:50] = True
    mesh = FeatureWarper(80, 60, mask).solve(load_warp(preset)(80, 60, **params))
    said = [w for w in mesh.record.warnings if "moves no pixel" in w]
    assert bool(said) == still, mesh.record.warnings


def test_a_grid_too_coarse_to_see_the_warp_is_named_as_the_cause_of_an_output_that_is_the_input():
    """--cell 10000 on 80 x 60: one quad, whose corners a swirl leaves in place, though it moves pixels
    by 18 px between them; the output is the input (no_effect stays true), but the warning blamed the
    options and asked whether the mask was inverted. Now it names the coarse grid, and the coverage
    warning names the cell."""
    mask = np.zeros((60, 80), bool)
    mask[20:40, 30:50] = True
    mesh = FeatureWarper(80, 60, mask, cell=10000).solve(load_warp("swirl")(80, 60, angle=90))
    assert mesh.record.grid["pl_error_px"] > 5 and mesh.record.no_effect, mesh.record.warnings
    still = [w for w in mesh.record.warnings if "moves no pixel" in w]
    assert len(still) == 1 and "the grid is too coarse to follow the warp" in still[0] and "options" not in still[0]
    assert any("strays up to" in w for w in mesh.record.warnings)
    assert any("or --cell 10000 too coarse for the mask's features?" in w for w in mesh.record.warnings)


def test_a_mask_over_all_the_warp_moves_is_not_called_a_warp_that_moves_nothing():
    """A bulge whose whole region the mask covers came out as the input, and besides the right
    warning said "the warp moves no pixel ... (options at their identity ...?)": it tested the
    result instead of the warp, and sent the user to options that were fine (photo trial 5)."""
    mask = np.ones((200, 200), bool)
    mesh = FeatureWarper(200, 200, mask).solve(load_warp("bulge")(200, 200, radius=0.25, strength=1.0))
    assert any("the mask covers the region the warp moves" in w for w in mesh.record.warnings), mesh.record.warnings
    assert not any("moves no pixel" in w for w in mesh.record.warnings), mesh.record.warnings


def test_a_mask_that_marks_nothing_says_what_it_read(tmp_path):
    """A mask painted pure red was read as empty with "no pixel >= 128", though every painted
    pixel was 255 in red: its gray is 76. The message now gives the brightest gray it read."""
    import cv2

    cv2.imwrite(str(tmp_path / "in.png"), np.random.default_rng(3).integers(0, 255, (60, 80, 3), dtype=np.uint8))
    red = np.zeros((60, 80, 3), np.uint8)
    red[20:40, 30:50, 2] = 255
    cv2.imwrite(str(tmp_path / "red.png"), red)
    cv2.imwrite(str(tmp_path / "dim.png"), red[:, :, 2] // 3)
    cv2.imwrite(str(tmp_path / "half.png"), np.full((60, 80), 32767, np.uint16))     # 127.5 of 255: not 128
    for mask, said in (("red.png", "its brightest pixel is 76, as colour is read as its gray"),
                       ("dim.png", "its brightest pixel is 85)"), ("half.png", "its brightest pixel is 127)")):
        run = CliRunner().invoke(cli, ["warp", "swirl", str(tmp_path / "in.png"), str(tmp_path / "o.png"),
                                       "-m", str(tmp_path / mask)])
        assert run.exit_code == 0 and said in run.output, run.output


def test_a_mask_drawn_on_the_stored_pixels_of_a_turned_photo_is_told_why_it_does_not_fit(tmp_path):
    """A phone JPEG stored 80x60 with EXIF orientation 6 is 60x80 upright; a mask drawn on the
    stored pixels got "mask is 80x60 but the image is 60x80" with no word of the orientation."""
    import cv2
    from PIL import Image

    exif = Image.Exif()
    exif[0x0112] = 6
    Image.fromarray(np.random.default_rng(3).integers(0, 255, (60, 80, 3), dtype=np.uint8)).save(
        tmp_path / "in.jpg", exif=exif.tobytes())
    cv2.imwrite(str(tmp_path / "m.png"), np.full((60, 80), 255, np.uint8))
    run = CliRunner().invoke(cli, ["warp", "swirl", str(tmp_path / "in.jpg"), str(tmp_path / "o.png"),
                                   "-m", str(tmp_path / "m.png")])
    assert run.exit_code == 2 and "mask is 80x60 but the image is 60x80 (upright, as its EXIF orientation" in run.output
    cv2.imwrite(str(tmp_path / "plain.png"), np.zeros((80, 60, 3), np.uint8))      # no EXIF: no such hint
    run = CliRunner().invoke(cli, ["warp", "swirl", str(tmp_path / "plain.png"), str(tmp_path / "o.png"),
                                   "-m", str(tmp_path / "m.png")])
    assert run.exit_code == 2 and "mask is 80x60 but the image is 60x80" in run.output and "EXIF" not in run.output


def test_a_frame_cut_feature_that_gives_way_leaves_the_others_exact():
    """Under fish (fixed border) the helmet, cut by two edges, cannot keep its shape and goes
    back to the plain warp's; untying it alone was refused because its minimum left a triangle
    under half its floor, though the result it replaced was thinner still (0.35 and 0.34 of
    the floor at 1 MP). Then every node moved to W: the head, which nothing had
    stopped from keeping its shape, came out as sheared as under the plain warp (1.107)."""
    import cv2

    from featurewarp_cli.engine.record import KEPT

    samples = Path(__file__).resolve().parent.parent / "samples"
    mask = cv2.resize(cv2.imread(str(samples / "astronaut_helmet_mask.png"), cv2.IMREAD_GRAYSCALE), (560, 560),
                      interpolation=cv2.INTER_LINEAR) >= 128
    mesh = FeatureWarper(560, 560, mask).solve(load_warp("fish")(560, 560), "similarity")
    head, helmet = mesh.record.components
    assert head.anisotropy_worst <= KEPT < head.plain_anisotropy_worst
    assert helmet.anisotropy_worst <= helmet.plain_anisotropy_worst * (1 + 1e-6)
    assert mesh.record.guard.degraded_components == [1]


def test_compare_says_when_it_has_no_mask_and_a_warp_at_rest_once(tmp_path):
    """Without --mask the three views were the plain warp, labelled as featurewarp's, in silence."""
    import cv2

    cv2.imwrite(str(tmp_path / "in.png"), np.random.default_rng(3).integers(0, 255, (60, 80, 3), dtype=np.uint8))
    run = CliRunner().invoke(cli, ["compare", "swirl", str(tmp_path / "in.png"), str(tmp_path / "o.png")])
    assert run.exit_code == 0 and "no --mask: the rigid and similarity views are the plain warp" in run.output
    run = CliRunner().invoke(cli, ["compare", "stretch", str(tmp_path / "in.png"), str(tmp_path / "p.png")])
    assert run.output.count("moves no pixel") == 1 and "all views: the warp moves no pixel" in run.output


@pytest.mark.parametrize("command", ["warp", "deform"])
def test_strict_writes_the_report_of_a_refused_run(tmp_path, command):
    """--strict with --report wrote no report when it refused: a CI gate had the first warning
    alone. The report is written, marked refused with every warning that caused it (output null);
    the image and the grid are not, and the exit is 1."""
    import json

    import cv2

    image, mask, handles = tmp_path / "in.png", tmp_path / "black.png", tmp_path / "h.json"
    cv2.imwrite(str(image), np.random.default_rng(3).integers(0, 255, (36, 48, 3), dtype=np.uint8))
    cv2.imwrite(str(mask), np.zeros((36, 48), np.uint8))           # marks no feature: a warning
    handles.write_text('{"version": 1, "points": [{"from": [2, 2], "to": [2, 2], "angel": 3}, '
                       '{"from": [40, 30], "to": [44, 30]}]}')   # an unknown key: a warning
    given = ["warp", "swirl"] if command == "warp" else ["deform", "--handles", str(handles)]
    out, report, grid = tmp_path / "o.png", tmp_path / "r.json", tmp_path / "g.npz"
    run = CliRunner().invoke(cli, given + [str(image), str(out), "-m", str(mask), "--strict",
                                           "--report", str(report), "--save-grid", str(grid)])
    assert run.exit_code == 1 and not out.exists() and not grid.exists(), run.output
    made = json.loads(report.read_text())                          # checked against the schema (conftest)
    error = made["refused"]["error"]
    assert made["output"] is None and run.output.strip().endswith(error)
    assert error.startswith("--strict: ") and error.endswith("; nothing written but the report")
    assert made["refused"]["warnings"] == made["warnings"] and len(made["warnings"]) == 1 + (command == "deform")
    written = CliRunner().invoke(cli, given + [str(image), str(out), "-m", str(mask), "--report", str(report)])
    assert written.exit_code == 0 and out.exists() and json.loads(report.read_text())["refused"] is None


def test_a_refusal_for_folds_reports_no_warning_as_its_cause_and_survives_a_failed_report():
    from types import SimpleNamespace

    from featurewarp_cli.app.pipeline import Settings, WarpError, check_solution

    mesh = SimpleNamespace(flips=lambda: 2, record=SimpleNamespace(warnings=["a warning"]))
    seen = []
    with pytest.raises(WarpError, match=r"2 folded triangles .*; nothing written but the report \(--allow"):
        check_solution(Settings("swirl", strict=True), mesh, lambda error, causes: seen.append(causes))
    assert seen == [[]]

    def fails(error, causes):
        raise WarpError("cannot write r.json: No space left on device")
    with pytest.raises(WarpError, match=r"; nothing written \(--allow-folds .*\) \(cannot write r.json: No space"):
        check_solution(Settings("swirl", strict=True), mesh, fails)


def test_a_rigid_feature_given_its_plain_scale_is_not_kept_and_says_its_scale():
    """A retoucher's trial: ``--size 50%x50% --mode rigid`` gave every feature W's scale 0.5
    (they cannot fit at full size: the guard released them) and read kept, with no warning and
    --strict passing; kept was judged on shape alone. In the rigid mode the size counts too;
    the similarity mode's scale is free."""
    import cv2

    mask = np.zeros((120, 160), np.uint8)
    cv2.circle(mask, (50, 60), 30, 255, -1)
    cv2.circle(mask, (115, 60), 30, 255, -1)             # two discs, one feature: 5 600 px of 4 800
    warper = FeatureWarper(160, 120, mask > 0)
    half, gentle = load_warp("stretch")(160, 120, sx=0.5, sy=0.5), load_warp("stretch")(160, 120, sx=0.9, sy=0.9)
    record = warper.solve(half, mode="rigid").record
    assert [round(c.scale, 2) for c in record.components] == [0.5] and not record.features_kept
    assert record.warnings[0].startswith("feature 0 (") and "not kept: scale 0.500 where the rigid mode keeps 1" \
        in record.warnings[0]
    record = warper.solve(gentle, mode="rigid").record
    assert [round(c.scale, 3) for c in record.components] == [1.0] and record.features_kept and not record.warnings
    record = warper.solve(half, mode="similarity").record
    assert [round(c.scale, 2) for c in record.components] == [0.5] and record.features_kept and not record.warnings


def test_a_feature_short_of_the_frame_says_how_far_its_edge_strip_follows_the_background(tmp_path):
    """A QA audit: a striped rectangle whose mask stops 1 px short of the right edge, under
    ``flag``, turned 6 degrees but kept its right side straight down the frame, and read kept
    with no warning: its pixels in the outer cells, which the frame holds, follow the
    background. Now a warning gives their count and how far they end from the feature's shape,
    and the --cell that keeps them in it; with that cell, nothing is said."""
    import json

    import cv2

    image = np.full((200, 399, 3), 200, np.uint8)        # 399: a --cell of gap + 0.5 leaves them there
    image[40:160, 330:399] = 40
    image[40:160:8, 330:399] = 250                      # stripes
    mask = np.zeros((200, 399), np.uint8)
    mask[40:160, 330:398] = 255                         # 1 px short of the right edge
    picture, mask_file, report_file = str(tmp_path / "in.png"), str(tmp_path / "m.png"), tmp_path / "r.json"
    cv2.imwrite(picture, image)
    cv2.imwrite(mask_file, mask)
    runner = CliRunner()

    def warp(*extra):
        run = runner.invoke(cli, ["warp", "flag", picture, str(tmp_path / "o.png"), "-m", mask_file, "--report",
                                  str(report_file), *extra])
        assert run.exit_code == 0, run.output
        return json.loads(report_file.read_text())

    report = warp()
    strip = report["components"]["items"][0]["frame_strip"]
    assert strip["sides"] == ["right"] and strip["off_px"] > 1.0 and 1.45 < strip["cell_px"] < 1.5
    line, = [w for w in report["warnings"] if "its mask stops just short of the right edge" in w]
    assert f"its {strip['pixels']} pixels in the frame's outer cells" in line
    assert f"--cell {strip['cell_px']:g} or finer may take" in line
    refused = runner.invoke(cli, ["warp", "flag", picture, str(tmp_path / "o2.png"), "-m", mask_file, "--strict"])
    assert refused.exit_code == 1 and not (tmp_path / "o2.png").exists()
    report = warp("--cell", str(strip["cell_px"]))      # in the feature (which this bend then does not keep: said)
    assert report["components"]["items"][0]["frame_strip"] is None
    assert not any("short of the right edge" in w for w in report["warnings"])
    mask[:, 330:] = 0
    mask[40:160, 330:380] = 255                          # 19 px short: a cell or more
    cv2.imwrite(mask_file, mask)
    report = warp()
    assert report["components"]["items"][0]["frame_strip"] is None and report["warnings"] == []


def test_a_no_op_says_whether_the_mask_covers_the_warp_or_rigid_holds_it_still():
    """A QA audit: a disc a fifth of a bulge's area, under --mode rigid, held at scale 1 where the
    bulge grows it, kept the rest still too, and the warning said the mask covers the region the
    warp moves. It now names the rigid mode; the similarity mode lets the disc scale."""
    import cv2

    mask = np.zeros((300, 400), np.uint8)
    cv2.circle(mask, (200, 150), 52, 255, -1)
    warper = FeatureWarper(400, 300, mask > 0)
    bulge = load_warp("bulge")(400, 300, strength=0.3)
    record = warper.solve(bulge, mode="rigid").record
    line, = [w for w in record.warnings if "the output is the input" in w]
    assert line.startswith("the rigid mode holds the features at their size where the warp would scale them")
    assert "(--mode similarity lets them scale)" in line and record.no_effect
    record = warper.solve(bulge, mode="similarity").record
    assert not record.no_effect and record.warnings == []


def test_a_frame_strip_is_said_of_a_feature_kept_only():
    """A false-alarm hunt: a speck merged with a large feature by the grid, not kept (said as
    such), got a frame-strip line too, its 2 pixels "33.8 px from its shape": the distance from
    the affine fit of a feature that has no one shape. A kept feature's strip is said."""
    from types import SimpleNamespace

    from featurewarp_cli.engine.record import ComponentRecord, SolveRecord, warnings_for

    strip = {"sides": ["top"], "pixels": 2, "off_px": 33.8, "cell_px": 3.469}
    record = SolveRecord("similarity", "exact", "fixed", {})
    record.components = [ComponentRecord(quads=40, tied=True, unpinned=False, scale=1.0, rotation_deg=0.0,
                                         distortion=worst, anisotropy_worst=worst, anisotropy_mean=worst,
                                         plain_distortion=0.5, plain_anisotropy_worst=0.5, area_ratio=1.0,
                                         kept=worst < 0.02, frame_strip=strip) for worst in (0.0, 4.4)]
    nodes = np.zeros((4, 2))
    lines = warnings_for(record, nodes, nodes, nodes, SimpleNamespace(canvas=(10, 10), width=20, height=20))
    strips = [line for line in lines if "its mask stops just short of the top edge" in line]
    assert len(strips) == 1 and strips[0].startswith("feature 0 (40 quads)")
    assert any(line.startswith("feature 1 (40 quads) not kept") for line in lines)
