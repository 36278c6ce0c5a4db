"""API conventions (issue 25, item 3): warnings of the package's own category, 0/1 masks."""

from __future__ import annotations

import os
import warnings

import numpy as np
import pytest

import featurewarp_cli
from featurewarp_cli import FeatureWarpWarning, warp
from featurewarp_cli.engine.arrays import mask_array
from featurewarp_cli.io.decode import mask_from_image


def test_warp_reports_what_it_could_not_do_as_warnings():
    """A mask that fills the swirl's disc: the output is the input, said as a FeatureWarpWarning."""
    image = np.random.default_rng(0).integers(0, 255, (60, 80, 3), dtype=np.uint8)
    mask = np.ones((60, 80), bool)
    with pytest.warns(FeatureWarpWarning) as caught:
        warp(image, mask, "swirl", angle=180)
    assert all(issubclass(w.category, UserWarning) for w in caught)
    with warnings.catch_warnings():
        warnings.simplefilter("error", FeatureWarpWarning)
        with pytest.raises(FeatureWarpWarning):
            warp(image, mask, "swirl", angle=180)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")                 # strict raises whatever the filters say
        with pytest.raises(FeatureWarpWarning, match="the output is the input"):
            warp(image, mask, "swirl", angle=180, strict=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warp(image, None, "swirl", angle=30)             # nothing to say: no warning at all


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int32, np.int64])
def test_a_zero_one_integer_mask_marks_its_ones(dtype):
    mask = np.zeros((4, 5), dtype)
    mask[1:3, 2:4] = 1
    np.testing.assert_array_equal(mask_array(mask, (4, 5)), mask == 1)
    if dtype in (np.uint8, np.uint16):
        np.testing.assert_array_equal(mask_from_image(mask), mask == 1)       # the command line's rule
    wide = mask * 255 if dtype != np.uint16 else mask * 65535
    wide[0, 0] = 1                                      # not a 0/1 mask: 1 is below the threshold
    assert not mask_array(wide.astype(dtype), (4, 5))[0, 0]


def test_the_package_says_it_is_typed():
    assert os.path.isfile(os.path.join(os.path.dirname(featurewarp_cli.__file__), "py.typed"))


@pytest.mark.parametrize("command", ["warp", "batch", "compare"])
def test_a_misspelt_preset_gets_a_suggestion(command):
    from click.testing import CliRunner

    from featurewarp_cli.cli.main import cli

    result = CliRunner().invoke(cli, [command, "swril", "in.png", "out.png"])
    assert result.exit_code == 2 and "did you mean 'swirl'?" in result.output


def test_the_api_suggests_too():
    from featurewarp_cli.plugins import UnknownPreset, load

    with pytest.raises(UnknownPreset, match="did you mean 'bulge'"):
        load("bulg")


def test_quiet_and_verbose_may_come_before_the_command(tmp_path):
    import cv2
    from click.testing import CliRunner

    from featurewarp_cli.cli.main import cli

    image = tmp_path / "in.png"
    cv2.imwrite(str(image), np.full((40, 60, 3), 90, np.uint8))
    mask = tmp_path / "m.png"
    cv2.imwrite(str(mask), np.full((40, 60), 255, np.uint8))       # fills the swirl: a warning is due
    runner = CliRunner()
    loud = runner.invoke(cli, ["warp", "swirl", str(image), str(tmp_path / "o.png"), "-m", str(mask)])
    assert loud.exit_code == 0 and "warning" in loud.output
    for args in (["-q", "warp", "swirl"], ["warp", "swirl", "-q"]):
        quiet = runner.invoke(cli, args + [str(image), str(tmp_path / "o.png"), "-m", str(mask)])
        assert quiet.exit_code == 0 and quiet.output == "", quiet.output
    verbose = runner.invoke(cli, ["-v", "warp", "swirl", str(image), str(tmp_path / "o.png")])
    assert verbose.exit_code == 0 and "swirl" in verbose.output
    same = runner.invoke(cli, ["-q", "diff", str(image), str(image)])
    assert same.exit_code == 0 and same.output == ""


def test_diff_json_prints_one_object_and_keeps_the_exit_status(tmp_path):
    import json

    import cv2
    from click.testing import CliRunner

    from featurewarp_cli.cli.main import cli

    a, b = tmp_path / "a.png", tmp_path / "b.png"
    cv2.imwrite(str(a), np.zeros((10, 12, 3), np.uint8))
    cv2.imwrite(str(b), np.full((10, 12, 3), 2, np.uint8))
    same = CliRunner().invoke(cli, ["diff", str(a), str(a), "--json"])
    assert same.exit_code == 0
    assert json.loads(same.output) == {"a": str(a), "b": str(a), "rmse": 0.0, "psnr": None, "max_abs": 0.0,
                                       "pixels_off": 0, "pixels": 120, "tolerance": 0.0, "within": True,
                                       "failures": []}
    off = CliRunner(mix_stderr=False).invoke(cli, ["diff", str(a), str(b), "--json", "--max-rmse", "1"]) \
        if "mix_stderr" in CliRunner.__init__.__code__.co_varnames else CliRunner().invoke(
            cli, ["diff", str(a), str(b), "--json", "--max-rmse", "1"])
    assert off.exit_code == 1
    line = json.loads(off.stdout.splitlines()[0])
    assert line["rmse"] == 2.0 and not line["within"] and "--max-rmse" in line["failures"][0]


def test_dash_dash_writes_stdin_in_its_own_format(tmp_path):
    """``cat in.png | featurewarp warp bulge - -``: stdout takes stdin's format, as ImageMagick's."""
    import subprocess
    import sys

    import cv2

    image = np.zeros((40, 60, 3), np.uint8)
    image[10:30, 20:40] = 200
    for ext, magic in ((".png", b"\x89PNG"), (".jpg", b"\xff\xd8\xff")):
        data = cv2.imencode(ext, image)[1].tobytes()
        run = subprocess.run([sys.executable, "-m", "featurewarp_cli", "warp", "bulge", "-", "-"], input=data,
                             capture_output=True, timeout=60)
        assert run.returncode == 0, run.stderr
        assert run.stdout.startswith(magic)


def test_batch_help_names_the_batch_options():
    from click.testing import CliRunner

    from featurewarp_cli.cli.main import cli

    text = CliRunner().invoke(cli, ["batch", "--help"]).output
    for option in ("--out-dir", "--jobs", "--scheduler", "--summary", "--resume", "--mask-pattern"):
        assert option in text, option


#: (preset, parameters, what the API says, what the command line says): one error, two namings.
NAMED = [
    ("swirl", {"angle": 900}, "angle: 900 is out of range (-540 <= DEG <= 540)",
     "Invalid value for '--angle': 900 is out of range (-540 <= DEG <= 540)"),
    ("arc", {"where": "lower", "angle": 171}, "angle: 171 is out of range when where is lower (at most 150)",
     "--angle: 171 is out of range when --where is lower (at most 150)"),
    ("perspective", {"tl": "60%,60%"}, "tl/tr/br/bl: the quadrilateral is concave at tl",
     "--tl/--tr/--br/--bl: the quadrilateral is concave at --tl"),
    ("cylinder", {"distance": 1.5}, "angle: 120 degrees wraps the cylinder too close to its silhouette seen from "
     "distance 1.5", "--angle: 120 degrees wraps the cylinder too close to its silhouette seen from --distance 1.5"),
    ("stretch", {"size": "0x10"}, "size: the width 0 is out of range (1 <= PX <= 65535)",
     "--size: the width 0 is out of range (1 <= PX <= 65535)"),
    ("stretch", {"feature_weight": 0}, "feature_weight: 0 is out of range (0.0001 <= W <= 10000)",
     "Invalid value for '--feature-weight': 0 is out of range (0.0001 <= W <= 10000)"),
]


@pytest.mark.parametrize("preset,params,api,command_line", NAMED, ids=[f"{c[0]}-{next(iter(c[1]))}" for c in NAMED])
def test_errors_name_api_parameters_in_the_api_and_flags_on_the_command_line(preset, params, api,
                                                                              command_line, tmp_path):
    """Issue 25 item 3: ``warp(..., angle=900)`` says ``angle: ...``; ``--angle 900`` says ``--angle``."""
    import cv2
    from click.testing import CliRunner

    from featurewarp_cli.cli.main import cli

    image = np.full((30, 40, 3), 128, np.uint8)
    with pytest.raises(ValueError) as err:
        warp(image, None, preset, **params)
    assert str(err.value).startswith(api) and "--" not in str(err.value)
    cv2.imwrite(str(tmp_path / "in.png"), image)
    args = [item for name, value in params.items() for item in (f"--{name.replace('_', '-')}", str(value))]
    run = CliRunner().invoke(cli, ["warp", preset, str(tmp_path / "in.png"), str(tmp_path / "o.png"), *args])
    assert run.exit_code == 2 and command_line in run.output, run.output


def test_a_parameter_error_crosses_process_boundaries_whole():
    """Batch workers send errors back pickled: the naming must survive."""
    import pickle

    from featurewarp_cli.plugins import ParamError, option_flag

    err = pickle.loads(pickle.dumps(ParamError("angle", "171 is out of range when `where` is lower", ("where",))))
    assert err.render(option_flag) == "--angle: 171 is out of range when --where is lower"
    assert str(err) == "angle: 171 is out of range when where is lower"


def test_array_dtypes_masks_and_orders_the_api_takes():
    """int8/int16 wrapped on return (opaque alpha -1), float16 came back black, an int64 0/255
    mask marked nothing, order="RGB" was silently BGR, a quick solve's info held NaN."""
    import json
    import warnings as warning_filters

    import numpy as np

    from featurewarp_cli import FeatureWarper, load_warp, warp

    image = np.random.default_rng(0).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    mask = np.zeros((48, 64), bool)
    mask[15:30, 20:40] = True
    with warning_filters.catch_warnings():
        warning_filters.simplefilter("ignore")
        small = warp((image // 2).astype(np.int8), mask, "swirl", angle=90)
        assert small.dtype == np.int8 and small.min() >= 0
        assert warp(image.astype(np.int16), mask, "arc", angle=90)[24, 32, 3] == 255     # 8-bit data: 8-bit alpha
        assert warp(image.astype(np.int16) * 100, mask, "arc", angle=90)[24, 32, 3] == np.iinfo(np.int16).max
        for kind in (np.int32, np.int64, np.uint32):             # wide integers are not clipped (NumPy 2)
            assert warp(image.astype(kind), mask, "swirl", angle=90).dtype == kind
        half = warp((image / 255).astype(np.float16), mask, "swirl", angle=90)
        assert half.dtype == np.float16 and abs(float(half.mean()) - float(image.mean()) / 255) < 0.05
    warper = FeatureWarper(64, 48, mask.astype(np.int64) * 255)
    assert warper.mask.sum() == mask.sum()
    mesh = warper.solve(load_warp("arc")(64, 48, angle=90))
    assert tuple(warper.render(image, mesh, background="red", order="bgr")[0, 0]) == (0, 0, 255)
    with pytest.raises(ValueError, match="order must be"):
        warper.render(image, mesh, order="RGB")
    quick = warper.solve(load_warp("swirl")(64, 48, angle=90), quick=True)
    json.dumps(quick.info, allow_nan=False)


def test_a_preset_that_breaks_the_warp_contract_is_named():
    import numpy as np

    from featurewarp_cli import FeatureWarper
    from featurewarp_cli.plugins import Warp

    class Endless(Warp):
        name = "endless"

        def forward(self, points):
            out = points * 1.0
            out[points[:, 0] > 40] = np.inf
            return out

    class Flat(Warp):
        name = "flat"

        def forward(self, points):
            return points[:, :1]

    for broken, message in ((Endless, "endless: .* not finite"), (Flat, r"flat: .* shape \(\d+, 1\)")):
        with pytest.raises(ValueError, match=message):
            FeatureWarper(64, 48).solve(broken(64, 48))


def test_the_deformer_moves_turned_handles_and_a_full_solve_has_no_history():
    """move() dropped each handle's angle; a full solve started the rigid map from the last one,
    so the same handles gave other bytes after another solve."""
    import numpy as np

    from featurewarp_cli import Deformer

    mask = np.zeros((120, 160), bool)
    mask[40:80, 60:100] = True
    turned = {"version": 2, "canvas": "input", "points": [{"from": [10, 10], "to": [10, 10]},
              {"from": [150, 110], "to": [150, 110]}, {"from": [80, 60], "to": [85, 60], "angle": 30}]}
    deformer = Deformer(160, 120, mask)
    first = deformer.solve(turned)
    moved = deformer.move([[10, 10], [150, 110], [85, 60]])
    assert deformer.handles.as_dict()["points"][2]["angle"] == 30
    np.testing.assert_allclose(moved.target, first.target, atol=1e-9)
    with pytest.raises(ValueError, match="3 points"):
        deformer.move([[1, 2], [3, 4]])
    pins = [{"from": [5, 110], "to": [5, 110]}, {"from": [150, 110], "to": [150, 110]}]
    def dragged(x, y):
        return {"version": 1, "points": pins + [{"from": [30, 10], "to": [x, y]}]}
    reused = Deformer(160, 120, mask)
    reused.solve(dragged(60, 4))
    np.testing.assert_array_equal(reused.solve(dragged(40, 8)).target, Deformer(160, 120, mask).solve(dragged(40, 8)).target)
