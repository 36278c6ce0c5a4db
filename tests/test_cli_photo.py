"""The retoucher trial (photo findings 10, 11 and nits 1-4): style names, the input's alpha as
its mask, the warp help, --grow-past-edge's crop on stderr, a run that moves nothing, arc's help."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_cli import SIZE, runner, save, scene, square_mask, textured  # noqa: F401  (runner: a fixture)

from featurewarp_cli.styles import style_owners, summary_styles


# --- style names (finding 10) ----------------------------------------------------------------

@pytest.mark.parametrize("name, preset, options", [
    ("fisheye", "bulge", []), ("twist", "swirl", []), ("twirl", "swirl", []),
    ("wave", "flag", ["--waves", "2"]), ("resize", "stretch", []), ("spherize", "sphere", []),
    ("Arc-Lower", "arc", ["--where", "lower"]), ("shellupper", "shell", ["--side", "upper"]),
    ("implode", "bulge", ["--strength", "-0.5"])])
def test_a_style_name_leads_to_its_preset(runner, name, preset, options):
    run = runner("warp", name, "in.png", "out.png", "-m", "m.png")
    assert run.code == 2
    line = " ".join(["featurewarp warp", preset, "in.png out.png -m m.png", *options])
    assert line in run.stderr and "did you mean" not in run.stderr, run.stderr
    assert run.stderr.count("\n") <= 2                     # usage line and the error, no traceback


#: What each style name must select: preset -> a test of the parameters it runs with.
SELECTS = {
    "fisheye": {"bulge": lambda p: p["strength"] > 0},
    "pinch": {"bulge": lambda p: p["strength"] < 0, "inflate": lambda p: p["bend"] < 0},
    "implode": {"bulge": lambda p: p["strength"] < 0},
    "twist": {"swirl": lambda p: p["angle"] != 0}, "twirl": {"swirl": lambda p: p["angle"] != 0},
    "wave": {"flag": lambda p: p["waves"] >= 2},
    "arclower": {"arc": lambda p: p["where"] == "lower"}, "arcupper": {"arc": lambda p: p["where"] == "upper"},
    "shelllower": {"shell": lambda p: p["side"] == "lower"}, "shellupper": {"shell": lambda p: p["side"] == "upper"},
    "lower": {"arc": lambda p: p["where"] == "lower", "shell": lambda p: p["side"] == "lower"},
    "upper": {"arc": lambda p: p["where"] == "upper", "shell": lambda p: p["side"] == "upper"},
    "spherize": {"sphere": lambda p: True}, "wrap": {"cylinder": lambda p: True, "sphere": lambda p: True},
    "distort": {"perspective": lambda p: True}, "nonuniform": {"stretch": lambda p: True},
    "resize": {"stretch": lambda p: True}, "scale": {"stretch": lambda p: True},
}


def suggested(stderr: str) -> list[list[str]]:
    """The command lines a style hint offers, as words."""
    import re
    import shlex

    return [shlex.split(line) for line in re.findall(r"featurewarp warp .*?(?= \(| or featurewarp|$)", stderr, re.M)]


def test_every_suggested_command_runs_and_gives_the_style(runner, tmp_path):
    """'pinch' was sent to plain bulge (which magnifies), 'arc-lower' and 'shellupper' to arc and
    shell without the --where / --side that selects them (review finding 1): every style the
    summaries name (and the unnamed ones) is offered a command that runs and selects it."""
    from featurewarp_cli import plugins
    from featurewarp_cli.styles import UNNAMED, _key

    image, _ = scene(tmp_path)
    named = {key for preset in plugins.BUILTIN for key in summary_styles(plugins.load(preset).summary)}
    styles = (named | set(UNNAMED)) - set(plugins.BUILTIN)
    assert styles == set(SELECTS)
    for style in sorted(styles):
        run = runner("warp", style, image, tmp_path / "o.png")
        commands = suggested(run.stderr)
        assert run.code == 2 and {words[2] for words in commands} == set(SELECTS[style]), (style, run.stderr)
        for words in commands:
            report = tmp_path / "r.json"
            done = runner(*words[1:], "--report", report)
            assert done.code == 0, (style, words, done.stderr)
            params = json.loads(report.read_text())["params"]
            assert SELECTS[_key(style)][words[2]](params), (style, words, params)


def test_a_style_hint_drops_what_the_preset_lacks_and_keeps_what_the_user_gave(runner, tmp_path):
    """fisheye --bend 30 was offered 'bulge ... --bend 30' (No such option: --bend); wave
    --waves 3 was offered '... --waves 3 --waves 2', the appended 2 winning (review finding 10)."""
    image, mask = scene(tmp_path)
    out = str(tmp_path / "o.png")
    run = runner("warp", "fisheye", image, out, "-m", mask, "--bend", "30")
    assert f"featurewarp warp bulge {image} {out} -m {mask} (--bend 30 left out: not an option of bulge)" \
        in run.stderr, run.stderr
    assert runner(*suggested(run.stderr)[0][1:]).code == 0
    run = runner("warp", "wave", image, out, "--waves", "3")
    assert suggested(run.stderr) == [["featurewarp", "warp", "flag", image, out, "--waves", "3"]], run.stderr
    run = runner("warp", "pinch", image, out, "--bend=30", "--strength", "0.2")
    lines = suggested(run.stderr)
    assert lines == [["featurewarp", "warp", "bulge", image, out, "--strength", "0.2"],
                     ["featurewarp", "warp", "inflate", image, out, "--bend=30"]], run.stderr
    assert "(Pinch is --strength -0.5; --strength kept as given)" in run.stderr
    for words in lines:
        assert runner(*words[1:]).code == 0


def test_fisheye_is_not_fish_and_a_misspelling_still_gets_the_nearest_name(runner):
    assert "'fish'" not in runner("warp", "fisheye", "a.png", "b.png").stderr
    assert "did you mean 'swirl'?" in runner("batch", "swril", "a.png", "-o", "out").stderr


def test_a_style_of_several_presets_names_them_all(runner):
    run = runner("compare", "lower", "a.png", "b.png")
    assert run.code == 2
    assert "featurewarp compare arc a.png b.png --where lower" in run.stderr
    assert "featurewarp compare shell a.png b.png --side lower" in run.stderr


def test_styles_come_from_the_summaries():
    styles = summary_styles("Flag (--waves 1) and Wave (--waves 2 or more) of Photoshop and Illustrator: a sine.")
    assert styles == {"flag": ("Flag", "--waves 1"), "wave": ("Wave", "--waves 2")}
    assert [owner[0] for owner in style_owners("photoshop")] == []


# --- the input's alpha as its mask (finding 11) -----------------------------------------------

def cut_out(tmp_path, name="cut.png", opaque=None):
    """An RGBA cut-out: the textured image, opaque over ``opaque`` (default: the square mask)."""
    alpha = square_mask() if opaque is None else opaque
    return save(tmp_path / name, np.dstack([textured(), alpha]))


def test_mask_alpha_is_the_inputs_alpha_as_a_mask_file(runner, tmp_path):
    image = cut_out(tmp_path)
    mask = save(tmp_path / "m.png", square_mask())
    assert runner("warp", "stretch", image, tmp_path / "a.png", "-m", "alpha", "--sx", "1.6").code == 0
    assert runner("warp", "stretch", image, tmp_path / "f.png", "-m", mask, "--sx", "1.6").code == 0
    assert runner("warp", "stretch", image, tmp_path / "p.png", "--sx", "1.6").code == 0
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "f.png").read_bytes()
    assert (tmp_path / "a.png").read_bytes() != (tmp_path / "p.png").read_bytes()


def test_half_opaque_marks_the_feature(runner, tmp_path):
    alpha = np.full(SIZE[::-1], 127, np.uint8)
    alpha[10:20, 10:20] = 128
    run = runner("warp", "stretch", cut_out(tmp_path, opaque=alpha), tmp_path / "a.png", "-m", "alpha",
                 "--sx", "1.6", "--report", tmp_path / "r.json")
    assert run.code == 0, run.stderr
    items = json.loads((tmp_path / "r.json").read_text())["components"]["items"]
    assert len(items) == 1 and items[0]["kept"] and abs(items[0]["at"][0] - 14.5) <= 2


def test_mask_alpha_without_alpha_is_one_line(runner, tmp_path):
    image, _ = scene(tmp_path)
    run = runner("warp", "stretch", image, tmp_path / "o.png", "-m", "alpha", "--sx", "1.5")
    assert run.code == 2 and "no alpha channel" in run.stderr and "Traceback" not in run.stderr
    assert not (tmp_path / "o.png").exists()


def test_an_alpha_that_marks_nothing_is_said(runner, tmp_path):
    image = cut_out(tmp_path, opaque=np.full(SIZE[::-1], 100, np.uint8))
    run = runner("warp", "stretch", image, tmp_path / "o.png", "-m", "alpha", "--sx", "1.5", "--strict")
    assert run.code == 1 and "alpha marks no feature" in run.stderr


def test_a_file_called_alpha_is_dot_slash_alpha(runner, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    image = cut_out(tmp_path)
    whole = np.zeros(SIZE[::-1], np.uint8)
    whole[:8, :8] = 255
    cv2_png = save(tmp_path / "alpha.png", whole)
    (tmp_path / "alpha").write_bytes((tmp_path / "alpha.png").read_bytes())
    run = runner("warp", "stretch", image, "a.png", "-m", "alpha", "--sx", "1.6")
    assert run.code == 0 and "--mask ./alpha" in run.stderr
    assert runner("warp", "stretch", image, "f.png", "-m", "./alpha", "--sx", "1.6").code == 0
    assert runner("warp", "stretch", image, "g.png", "-m", cv2_png, "--sx", "1.6").code == 0
    assert (tmp_path / "f.png").read_bytes() == (tmp_path / "g.png").read_bytes() != (tmp_path / "a.png").read_bytes()


def test_a_file_called_alpha_beside_an_input_without_alpha_is_pointed_to(runner, tmp_path, monkeypatch):
    """-m alpha read the file 'alpha' before it meant the alpha channel: on an input without
    alpha the error said "give a mask file", not how to read that file (review finding 8)."""
    monkeypatch.chdir(tmp_path)
    image, mask = scene(tmp_path)
    run = runner("warp", "stretch", image, "o.png", "-m", "alpha", "--sx", "1.5")
    assert run.code == 2 and "give a mask file" in run.stderr and "./alpha" not in run.stderr
    (tmp_path / "alpha").write_bytes(open(mask, "rb").read())
    run = runner("warp", "stretch", image, "o.png", "-m", "alpha", "--sx", "1.5")
    assert run.code == 2 and "no alpha channel" in run.stderr and "give --mask ./alpha" in run.stderr, run.stderr
    assert runner("warp", "stretch", image, "o.png", "-m", "./alpha", "--sx", "1.5").code == 0


def test_batch_takes_each_inputs_own_alpha(runner, tmp_path):
    other = np.zeros(SIZE[::-1], np.uint8)
    other[2:12, 30:44] = 255
    first, second = cut_out(tmp_path, "a.png"), cut_out(tmp_path, "b.png", other)
    run = runner("batch", "stretch", first, second, "-o", tmp_path / "out", "--mask-pattern", "alpha", "--sx", "1.6")
    assert run.code == 0, run.stderr
    for name, image in (("a.png", first), ("b.png", second)):
        assert runner("warp", "stretch", image, tmp_path / name, "-m", "alpha", "--sx", "1.6").code == 0
        assert (tmp_path / "out" / name).read_bytes() == (tmp_path / name).read_bytes()
    opaque, _ = scene(tmp_path, "c.png")
    run = runner("batch", "stretch", opaque, "-o", tmp_path / "out2", "--mask-pattern", "alpha")
    assert run.code == 1 and "c.png: --mask-pattern: the input has no alpha channel" in run.stderr
    assert "give --mask-pattern a file pattern, such as '{stem}_mask.png'" in run.stderr    # not "a mask file"
    assert "give a mask file" not in run.stderr and "--mask:" not in run.stderr


@pytest.mark.parametrize("args", [["compare", "stretch", "{in}", "{out}.png", "--sx", "1.5"],
                                  ["animate", "swirl", "{in}", "{out}.gif", "--vary", "angle=0:60", "--frames", "2"],
                                  ["deform", "{in}", "{out}.png", "--move", "24,18:28,18", "--pin", "2,2"]])
def test_the_other_commands_take_the_alpha(runner, tmp_path, args):
    image = cut_out(tmp_path)
    filled = [a.replace("{in}", image).replace("{out}", str(tmp_path / "o")) for a in args]
    run = runner(*filled, "-m", "alpha")
    assert run.code == 0, run.stderr
    image, _ = scene(tmp_path)
    filled = [a.replace("{in}", image).replace("{out}", str(tmp_path / "p")) for a in args]
    assert "no alpha channel" in runner(*filled, "-m", "alpha").stderr


# --- the help (nit 1) ---------------------------------------------------------------------------

def test_warp_help_names_the_common_options_and_how_to_make_a_mask(runner):
    text = runner("warp", "--help").stdout.decode()
    for word in ("--mask PATH|alpha", "--mode", "--report", "--strict", "--grow-past-edge",
                 "featurewarp warp PRESET --help", "featurewarp edit INPUT --save-mask", "-alpha extract"):
        assert word in text, word


def test_a_presets_help_puts_its_own_options_first_in_plain_words(runner):
    text = runner("warp", "stretch", "--help").stdout.decode()
    options = text[text.index("Options:"):]
    assert options.index("--sx") < options.index("--size") < options.index("--mask") < options.index("--mode")
    assert "w_F:" not in text and "(w_F-weighted)" not in text and "double precision" not in text
    assert "(the paper's rho)" in text                     # the paper's term kept in brackets
    batch = runner("batch", "swirl", "--help").stdout.decode()
    assert batch.index("--angle") < batch.index("--mode")


# --- --grow-past-edge says what it crops (nit 2) ------------------------------------------------

SAMPLES = __import__("pathlib").Path(__file__).resolve().parent.parent / "samples"


def test_grow_past_edge_says_where_it_crops(runner, tmp_path):
    args = ["warp", "stretch", SAMPLES / "closeup.png", tmp_path / "g.png", "-m", SAMPLES / "closeup_mask.png",
            "--sy", "1.5", "--grow-past-edge", "--report", tmp_path / "g.json"]
    run = runner(*args, "--strict")                      # the crop is what the option asks: no warning
    assert run.code == 0, run.stderr
    past = json.loads((tmp_path / "g.json").read_text())["grown"]["past_px"]
    assert run.lines == [f"featurewarp: {SAMPLES / 'closeup.png'}: --grow-past-edge grew the features cut by the "
                         f"frame {json.loads((tmp_path / 'g.json').read_text())['grown']['k']:.2f}x: the image runs "
                         f"past the left edge by {past['left']:.0f} px and the right edge by {past['right']:.0f} px, "
                         f"cropped there"]
    assert runner(*args, "-q").stderr == ""


# --- a run that moves nothing (nit 4) -----------------------------------------------------------

def report_of(runner, tmp_path, *args):
    image, mask = scene(tmp_path)
    run = runner("warp", *args[:1], image, tmp_path / "o.png", "--report", tmp_path / "r.json",
                 *[mask if a == "MASK" else a for a in args[1:]])
    assert run.code == 0, run.stderr
    return json.loads((tmp_path / "r.json").read_text())


def test_the_report_says_when_the_output_is_the_input(runner, tmp_path):
    whole = save(tmp_path / "whole.png", np.full(SIZE[::-1], 255, np.uint8))
    covered = report_of(runner, tmp_path, "swirl", "-m", whole, "--angle", "180", "--radius", "0.5")
    assert covered["features_kept"] is True and covered["no_effect"] is True
    assert any("the output is the input" in w for w in covered["warnings"])
    still = report_of(runner, tmp_path, "stretch", "-m", "MASK")
    assert still["no_effect"] is True
    moved = report_of(runner, tmp_path, "stretch", "-m", "MASK", "--sx", "1.5")
    assert moved["no_effect"] is False and not any("the output is the input" in w for w in moved["warnings"])
    assert report_of(runner, tmp_path, "swirl", "--mode", "plain", "--angle", "90")["no_effect"] is False


# --- arc and ImageMagick's -distort Arc (nit 3) -------------------------------------------------

def test_arcs_help_says_where_its_geometry_leaves_imagemagicks(runner):
    import math

    from featurewarp_cli import load_warp

    arc = load_warp("arc")
    wide = arc(600, 300, angle=90)                 # ImageMagick's default top radius: w / angle + h / 2
    assert wide.r_outer == pytest.approx(600 / math.radians(90) + 150)
    assert tuple(arc(600, 600, angle=120).canvas) == (1144, 630)     # ImageMagick: 1016x595, folded
    text = " ".join(runner("warp", "arc", "--help").stdout.decode().split())
    assert "except where those leave an inner radius under a tenth of the height" in text and "1016x595" in text


def test_the_python_api_answers_a_style_name_with_its_preset_too():
    """load_warp('fisheye') said "did you mean 'fish'?" (the Fish style), as the command line
    did before it read the presets' summaries."""
    from featurewarp_cli import load_warp
    from featurewarp_cli.plugins import UnknownPreset

    with pytest.raises(UnknownPreset, match="Fisheye is bulge's style") as caught:
        load_warp("fisheye")
    assert "fish'" not in str(caught.value)
    with pytest.raises(UnknownPreset, match="did you mean 'swirl'"):
        load_warp("swrl")


def test_a_style_hint_under_animate_keeps_the_varied_option_and_drops_one_the_preset_lacks():
    """animate wave --vary waves=1:3 was told to run flag ... --vary waves=1:3 --waves 2, which
    animate refuses (given and varied); pinch's inflate command kept --vary strength=..., which
    inflate does not have (smoke trial 1)."""
    from featurewarp_cli.styles import merged

    table = {"--vary": ("vary", True), "--frames": ("frames", True), "--waves": ("waves", True),
             "--bend": ("bend", True)}
    kept, dropped, yields = merged(["--vary", "waves=1:3", "--frames", "3"], "--waves 2", table, {})
    assert kept == ["--vary", "waves=1:3", "--frames", "3"] and yields and not dropped
    kept, dropped, _ = merged(["--vary=strength=-0.2:-0.5"], "--bend -40", table, {})
    assert kept == ["--bend", "-40"] and dropped == ["--vary=strength=-0.2:-0.5"]


def test_a_batch_summary_keeps_the_crop_note(runner, tmp_path):
    """A batch printed --grow-past-edge's crop on stderr but its --summary line had warnings
    only: a nightly job reading the summary never learnt that its outputs were cropped."""
    summary = tmp_path / "runs.jsonl"
    run = runner("batch", "stretch", SAMPLES / "closeup.png", "--out-dir", tmp_path / "out",   # closeup_mask.png
                 "--sy", "1.5", "--grow-past-edge", "--summary", summary)
    assert run.code == 0, run.stderr
    line = json.loads(summary.read_text())
    assert line["warnings"] == [] and line["notes"] and "cropped there" in line["notes"][0]
    assert line["notes"][0] in run.stderr
