"""What the Python API takes and says (trial s28): images, masks, options, presets, warnings."""

from __future__ import annotations

import ast
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

import featurewarp_cli
from featurewarp_cli import FeatureWarpWarning, warp
from featurewarp_cli.engine import api, arrays
from featurewarp_cli.plugins import ParamError, Warp

ROOT = Path(__file__).resolve().parent.parent


def picture(h=24, w=32, channels=3):
    rng = np.random.default_rng(1)
    return rng.integers(0, 256, (h, w, channels) if channels else (h, w), dtype=np.uint8)


def box(h=24, w=32):
    mask = np.zeros((h, w), bool)
    mask[8:16, 10:20] = True
    return mask


def quiet(*args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return warp(*args, **kwargs)


class NoSolve(Exception):
    pass


@pytest.fixture
def no_solve(monkeypatch):
    """Fails the test's warp() if it gets as far as building a FeatureWarper."""
    def refuse(*args, **kwargs):
        raise NoSolve
    monkeypatch.setattr(api, "FeatureWarper", refuse)


BAD_IMAGES = [
    (lambda: picture().ravel(), ValueError, r"not shape \(2304,\)"),
    (lambda: picture()[None], ValueError, r"\(1, 24, 32, 3\) \(one image at a time"),
    (lambda: picture().astype(np.float32), ValueError, r"float image must hold values in \[0, 1\].*0\.0\.\.25\d"),
    (lambda: picture()[:0], ValueError, "no pixels"),
    (lambda: "in.png", TypeError, "not a path"),
    (lambda: picture().astype(complex), ValueError, "dtype complex128 is not supported"),
]


@pytest.mark.parametrize("make,kind,message", BAD_IMAGES)
def test_a_bad_image_is_named_before_the_solve(no_solve, make, kind, message):
    with pytest.raises(kind, match=message):
        warp(make(), None, "swirl")


def test_a_bad_background_or_mask_is_named_before_the_solve(no_solve):
    with pytest.raises(ValueError, match=r"background must be .* not \(300, 0, 0\)"):
        warp(picture(), None, "swirl", background=(300, 0, 0))
    with pytest.raises(ValueError, match=r"mask must be \(h, w\).*not shape \(24, 32, 5\)"):
        warp(picture(), np.zeros((24, 32, 5), bool), "swirl")
    with pytest.raises(ValueError, match="mask is 32x20, image is 32x24"):
        warp(picture(), np.zeros((20, 32), bool), "swirl")
    with pytest.raises(ValueError, match="3 channels must be uint8 or uint16.*not float32"):
        warp(picture(), np.zeros((24, 32, 3), np.float32), "swirl")
    with pytest.raises(ValueError, match="mask: cannot read"):
        warp(picture(), "no/such/mask.png", "swirl")


def test_lists_and_pil_images_are_arrays():
    from PIL import Image

    image = picture()
    expected = quiet(image, box(), "swirl", angle=60)
    np.testing.assert_array_equal(quiet(image.tolist(), box(), "swirl", angle=60), expected)
    np.testing.assert_array_equal(quiet(Image.fromarray(image), box(), "swirl", angle=60), expected)


def test_a_pil_image_is_taken_as_its_pixels_whatever_its_mode():
    """np.asarray of a palette image is its colour indices (warped as grey, silently), of a CMYK
    one four channels taken as RGBA (K as alpha): they are converted first; L*a*b* is refused."""
    from PIL import Image

    image = picture()
    rgb = Image.fromarray(image)
    palette = rgb.quantize(64)
    np.testing.assert_array_equal(quiet(palette, box(), "swirl", angle=60),
                                  quiet(np.asarray(palette.convert("RGB")), box(), "swirl", angle=60))
    palette.info["transparency"] = 0
    assert quiet(palette, box(), "swirl", angle=60).shape[2] == 4
    cmyk = rgb.convert("CMYK")
    np.testing.assert_array_equal(quiet(cmyk, box(), "swirl", angle=60),
                                  quiet(np.asarray(cmyk.convert("RGB")), box(), "swirl", angle=60))
    with pytest.raises(ValueError, match="mode LAB"):
        warp(rgb.convert("LAB"), box(), "swirl", angle=60)


def test_a_mesh_is_its_own_and_renders_only_its_image_size():
    """Every mesh of a warper shared its source array with the warper's cache (an edit of one
    changed every later solve), and a mesh of another size rendered a crop."""
    from featurewarp_cli import FeatureWarper, load_warp

    image = picture()
    height, width = image.shape[:2]
    warper = FeatureWarper(width, height, box())
    first = warper.solve(load_warp("swirl")(width, height, angle=45))
    first.source[:, 0] += 5.0
    second = warper.solve(load_warp("swirl")(width, height, angle=90))
    fresh = FeatureWarper(width, height, box())
    np.testing.assert_array_equal(warper.render(image, second),
                                  fresh.render(image, fresh.solve(load_warp("swirl")(width, height, angle=90))))
    small = FeatureWarper(width // 2, height // 2)
    with pytest.raises(ValueError, match=f"mesh is for a {width // 2}x{height // 2} image, not {width}x{height}"):
        warper.render(image, small.solve(load_warp("swirl")(width // 2, height // 2, angle=60)))


def test_handles_made_directly_are_checked_as_a_files_are():
    """Handles(...) made directly skipped every check: NaN gave numpy's and scipy's errors, a
    source outside the image was taken, lists failed with a TypeError."""
    from featurewarp_cli import Deformer, Handles

    deformer = Deformer(160, 120, box(120, 160))
    with pytest.raises(ValueError, match=r"^points\[1\]\.to: expected a point \[x, y\] of two finite numbers"):
        Handles(np.array([[10.0, 10], [150, 110]]), np.array([[10.0, 10], [np.nan, 100]]))
    with pytest.raises(ValueError, match=r"^points\[1\]\.from \(2000, 110\) lies outside the 160x120 image"):
        deformer.solve(Handles(np.array([[10.0, 10], [2000, 110]]), np.array([[10.0, 10], [140, 100]])))
    with pytest.raises(ValueError, match="2 sources but 1 targets"):
        Handles([[10.0, 10], [150, 110]], [[10.0, 10]])
    mesh = deformer.solve(Handles([[10.0, 10], [150, 110]], [[10.0, 10], [140, 100]]))      # lists: taken
    assert mesh.flips() == 0


def test_a_warpers_cell_and_flags_are_checked_as_warps_are():
    """FeatureWarper took ``cell=True`` as a 1 px grid and ``injective="no"`` (and render's
    ``antialias="no"``) as true, where warp() refuses them."""
    from featurewarp_cli import FeatureWarper, load_warp

    for options, message in (({"cell": True}, "cell must be a number of pixels"),
                             ({"injective": "no"}, "injective must be True or False, not 'no'"),
                             ({"grow_past_edge": "no"}, "grow_past_edge must be True or False")):
        with pytest.raises(ValueError, match=message):
            FeatureWarper(32, 24, box(), **options)
    warper = FeatureWarper(32, 24, box(), injective=np.bool_(True))
    mesh = warper.solve(load_warp("swirl")(32, 24, angle=60))
    with pytest.raises(ValueError, match="antialias must be True or False"):
        warper.render(picture(), mesh, antialias="no")


def test_solve_names_a_preset_class_or_name_given_for_its_instance():
    """``FeatureWarper.solve(Swirl)`` (the class, as warp() takes it) and ``solve("swirl")`` failed
    with AttributeError: 'type' object has no attribute 'width'."""
    from featurewarp_cli import FeatureWarper, load_warp

    warper, swirl = FeatureWarper(32, 24, box()), load_warp("swirl")
    for given, message in ((swirl, r"not the class Swirl: make it for the image, Swirl\(32, 24\)"),
                           ("swirl", r"load_warp\('swirl'\)\(32, 24\) makes a preset"), (None, "not NoneType")):
        with pytest.raises(TypeError, match=message):
            warper.solve(given)
    with pytest.raises(ValueError, match="warp is for 24x32, warper for 32x24"):
        warper.solve(swirl(24, 32))
    assert warper.solve(swirl(32, 24)).target.shape[1] == 2


def test_integer_images_of_eight_bit_data_keep_the_eight_bit_scale():
    """An int32 image of 0..255 data came back with alpha and white at 65535 and cubic overshoot past 255."""
    image, mask = picture(), box()
    for kind in (np.int16, np.int32, np.int64):
        for preset, options in (("swirl", {"angle": 120}), ("arc", {"angle": 90}), ("arc", {"background": "white"})):
            got = quiet(image.astype(kind), mask, preset, **options)
            assert got.dtype == kind
            np.testing.assert_array_equal(got, quiet(image, mask, preset, **options).astype(kind))
    wide = image.astype(np.int32) * 200                 # beyond 255: the 16-bit scale
    np.testing.assert_array_equal(quiet(wide, mask, "arc", angle=90),
                                  quiet(wide.astype(np.uint16), mask, "arc", angle=90).astype(np.int32))


def test_a_grey_image_keeps_its_channel_axis_and_takes_a_grey_background():
    grey = picture(channels=1)
    flat = quiet(grey[..., 0], box(), "arc", angle=90)
    kept = quiet(grey, box(), "arc", angle=90)
    assert flat.ndim == 3 and flat.shape[2] == 2 and kept.shape == flat.shape      # gained alpha: (grey, alpha)
    filled = quiet(grey, box(), "arc", angle=90, background=128)
    assert filled.ndim == 3 and filled.shape[2] == 1 and filled[0, 0, 0] == 128
    np.testing.assert_array_equal(filled[..., 0], quiet(grey[..., 0], box(), "arc", angle=90, background=128))
    assert tuple(quiet(picture(), box(), "arc", angle=90, background=128)[0, 0]) == (128, 128, 128)
    with pytest.raises(ValueError, match="not 256"):
        arrays.background_rgb(256)


def test_masks_with_channels_and_paths_follow_the_command_lines_rule(tmp_path):
    """A (h, w, 1) mask, an RGB(A) mask and a path were refused ('mask is 128x128, image is 128x128')."""
    import cv2

    from featurewarp_cli.io.decode import mask_from_image

    mask = box()
    grey = mask.astype(np.uint8) * 200
    np.testing.assert_array_equal(arrays.mask_array(mask[..., None], mask.shape), mask)
    np.testing.assert_array_equal(arrays.mask_array(np.dstack([grey] * 3), mask.shape), mask)
    red = np.zeros((24, 32, 3), np.uint8)
    red[..., 0] = grey                                  # pure red reads as its gray, 59: nothing
    assert not arrays.mask_array(red, mask.shape).any()
    blue_bgr = red.copy()                               # the same colours as OpenCV's BGR, as a file holds them
    np.testing.assert_array_equal(arrays.mask_array(red, mask.shape), mask_from_image(blue_bgr[..., ::-1]))
    rgba = np.dstack([np.full((24, 32, 3), 255, np.uint8), grey])      # white, transparent outside the box
    np.testing.assert_array_equal(arrays.mask_array(rgba, mask.shape), mask)
    np.testing.assert_array_equal(arrays.mask_array(np.dstack([grey, grey]), mask.shape), mask)
    cv2.imwrite(str(tmp_path / "m.png"), grey)
    np.testing.assert_array_equal(arrays.mask_array(tmp_path / "m.png", mask.shape), mask)
    np.testing.assert_array_equal(quiet(picture(), str(tmp_path / "m.png"), "swirl", angle=90),
                                  quiet(picture(), mask, "swirl", angle=90))


def test_a_thin_image_is_told_as_thin_not_as_an_empty_mask():
    """A valid mask on a 3 px image was said to mark no feature, and strict raised that."""
    image = np.zeros((3, 40, 3), np.uint8)
    mask = np.zeros((3, 40), bool)
    mask[1, 10:20] = True
    with pytest.warns(FeatureWarpWarning) as caught:
        warp(image, mask, "stretch", sx=2)
    assert [str(w.message) for w in caught] == [
        "the image is 40x3: too thin for a feature to keep a shape (under 4 px); the mask is ignored"]
    with pytest.raises(FeatureWarpWarning, match="too thin"):
        warp(image, mask, "stretch", sx=2, strict=True)
    with pytest.warns(FeatureWarpWarning, match="marks no feature"):
        warp(picture(), np.zeros((24, 32), bool), "swirl", angle=90)


def test_options_are_checked_and_named_as_the_api_names_them(no_solve):
    """strict='no' was true, max_nodes was blamed on the preset, warp()'s own options raised plain ValueErrors."""
    for options, names, message in (
            ({"strict": "no"}, ("strict",), "must be True or False, not 'no'"),
            ({"interp": "bicubic"}, ("interp",), "must be one of nearest"),
            ({"mode": "affine"}, ("mode",), "must be one of similarity"),
            ({"max_nodes": 10}, ("max_nodes",), r"neither warp\(\) nor swirl takes it.*'max_memory'.*warp\(\) "
                                                 r"takes mode, .*return_mesh; swirl takes angle"),
            ({"max_memory": "lots"}, ("max_memory",), "'lots' is not a size"),
            ({"max_memory": 100}, ("max_memory",), r"above the memory limit of 100 bytes \(max_memory\)")):
        with pytest.raises(ParamError, match=message) as err:
            warp(picture(), None, "swirl", **options)
        assert err.value.names == names and "--" not in str(err.value)


def test_warpers_own_errors_are_param_errors_in_api_terms():
    with pytest.raises(ParamError, match=r"^cell: 1 makes a grid of 825 nodes, above the \d+ that the memory "
                                         r"limit allows \(a larger cell, or a larger max_memory\)$"):
        warp(picture(), None, "swirl", cell=1, max_memory="300K")
    with pytest.raises(ParamError, match="^boundary: must be one of"):
        warp(picture(), None, "swirl", boundary="loose")
    from featurewarp_cli.engine.fidelity import GridBudgetError

    with pytest.raises(GridBudgetError, match=r"above the \d+ that the memory limit allows \(a larger max_memory"):
        warp(picture(), None, "swirl", angle=500, max_memory="300K")
    quiet(picture(), None, "swirl", angle=30, max_memory="300K")        # a grid it holds


def test_return_mesh_gives_the_record_whose_lines_were_warned():
    with pytest.warns(FeatureWarpWarning) as caught:
        out, mesh = warp(picture(), np.zeros((24, 32), bool), "stretch", sx=0.01, return_mesh=True)
    assert out.shape[1] == 1 and [str(w.message) for w in caught] == mesh.record.warnings
    assert mesh.record.warnings[0].startswith("the mask marks no feature")
    assert "sx 0.01 makes the width 0.32 px: it is 1 px" in mesh.record.warnings   # stretch's review, API-named
    assert not any("--" in line for line in mesh.record.warnings)


class Fold(Warp):
    """Folds the image about its middle column."""

    name = "fold"

    def forward(self, points):
        out = points.copy()
        out[:, 0] = np.abs(points[:, 0] - self.width / 2) + self.width / 2
        return out


def test_a_preset_class_or_instance_is_taken_and_folds_are_said():
    """A Warp class failed inside difflib; a folded result came back without a word."""
    with pytest.warns(FeatureWarpWarning) as caught:
        warp(picture(), None, Fold, cell=8)
    lines = [str(w.message) for w in caught]
    assert re.match(r"the result has \d+ folded triangles", lines[0])
    assert any("a finer cell" in line for line in lines) and not any("--" in line for line in lines)
    with pytest.raises(FeatureWarpWarning, match="folded triangles"):
        warp(picture(), None, Fold(32, 24), cell=8, strict=True)
    with pytest.raises(ValueError, match="made for 16x16, the image is 32x24"):
        warp(picture(), None, Fold(16, 16))
    with pytest.raises(ParamError, match="instance"):
        warp(picture(), None, Fold(32, 24), angle=3)
    with pytest.raises(TypeError, match="preset must be a preset's name.*not 5"):
        warp(picture(), None, 5)


def test_type_checkers_and_dir_see_the_public_names():
    """Every name was Any to type checkers and dir() did not list warp, FeatureWarper, ..."""
    assert set(featurewarp_cli.__all__) <= set(dir(featurewarp_cli))
    tree = ast.parse((ROOT / "featurewarp_cli" / "__init__.py").read_text())
    block = next(node for node in tree.body if isinstance(node, ast.If) and getattr(node.test, "id", "") == "TYPE_CHECKING")
    typed = {alias.name for node in block.body for alias in node.names}
    defined = {node.name for node in tree.body if isinstance(node, ast.ClassDef)} | {"__version__"}
    assert typed == set(featurewarp_cli.__all__) - defined
    for name in typed:
        assert getattr(featurewarp_cli, name) is not None



def test_the_readme_api_example_closes_its_file():
    text = (ROOT / "README.md").read_text()
    section = text[text.index("\n## Python API"):text.index("\n## ", text.index("\n## Python API") + 1)]
    assert not re.search(r"^(?!\s*with ).*(?<![.\w])open\(", section, re.M)
    assert "OPENBLAS_NUM_THREADS" in section


def test_a_warper_renders_lists_and_keeps_a_channel_axis_and_reads_mask_paths(tmp_path):
    """FeatureWarper itself takes what warp() takes: a mask path (it said "mask is , image is
    50x40"), a list image, and an (h, w, 1) image keeps its channel axis (API trial)."""
    import cv2

    from featurewarp_cli import FeatureWarper, load_warp

    mask = np.zeros((40, 50), np.uint8)
    mask[10:20, 10:20] = 255
    cv2.imwrite(str(tmp_path / "m.png"), mask)
    warper = FeatureWarper(50, 40, str(tmp_path / "m.png"))
    assert warper.mask.sum() == 100
    mesh = warper.solve(load_warp("swirl")(50, 40))
    image = np.zeros((40, 50, 1), np.uint8)
    assert warper.render(image, mesh).shape == warper.render(image.tolist(), mesh).shape == (40, 50, 1)


@pytest.mark.parametrize("size", [(0, 240), (-5, 10), (10.5, 10), (True, 10)])
def test_impossible_sizes_are_refused_at_once(size):
    """Deformer(0, 240) was taken and failed in the factorization ("not positive definite"),
    Deformer(-5, ...) with numpy's "negative dimensions" (smoke trial 5)."""
    from featurewarp_cli import Deformer, FeatureWarper

    for cls in (FeatureWarper, Deformer):
        with pytest.raises(ValueError, match=rf"{cls.__name__}: width=.*whole number of pixels"):
            cls(*size)


def test_a_nan_mask_is_refused_and_a_whole_float_max_memory_is_bytes():
    """A float mask with NaN in its features was a plain warp with "marks no feature"; 2e9 was
    "not a size" (smoke trial nits)."""
    from featurewarp_cli import warp

    image = np.zeros((40, 50, 3), np.uint8)
    mask = np.zeros((40, 50))
    mask[10:20, 10:20] = np.nan
    with pytest.raises(ValueError, match="mask holds NaN"):
        warp(image, mask, "swirl")
    mask[10:20, 10:20] = 1.0
    assert warp(image, mask, "swirl", max_memory=2e9).shape == (40, 50, 3)


def test_a_pil_palette_mask_is_read_by_its_colours_not_its_indices():
    """A palette ("P") mask whose index 0 is white marked the black pixels (its indices 0/1 read
    as a 0/1 mask): the mask inverted, silently; a path to the same file was read right."""
    from PIL import Image

    marked = box()
    palette = Image.fromarray((~marked).astype(np.uint8), mode="P")
    palette.putpalette([255, 255, 255, 0, 0, 0] + [0] * 762)
    np.testing.assert_array_equal(arrays.mask_array(palette, marked.shape), marked)
    np.testing.assert_array_equal(quiet(picture(), palette, "swirl", angle=60),
                                  quiet(picture(), marked, "swirl", angle=60))


def test_big_endian_uint16_is_uint16():
    """A big-endian uint16 image (">u2" != np.uint16) whose values are all below 256 was read
    on the 8-bit scale: its added alpha was 255 of 65535 (nearly transparent); a big-endian
    uint16 mask took the 8-bit threshold (128, not 32896)."""
    dark = np.random.default_rng(2).integers(0, 200, (24, 32), dtype=np.uint16)
    native = quiet(dark, box(), "arc", angle=90)
    swapped = quiet(dark.astype(">u2"), box(), "arc", angle=90)
    assert swapped.dtype == np.dtype(">u2")
    np.testing.assert_array_equal(swapped, native)
    soft = np.where(box(), 65535, 1000).astype(np.uint16)
    np.testing.assert_array_equal(arrays.mask_array(soft.astype(">u2"), soft.shape), box())


@pytest.mark.parametrize("canvas", [(32.5, 24), (0, 0), (-5, 10), (32,), (True, 24), "32x24"])
def test_a_plugins_bad_canvas_is_named(no_solve, canvas):
    """A plugin's canvas of (0, 0) failed in the rasterizer ("triangles: buffer sizes do not
    match"), (32.5, 24) with a TypeError deep in the render, (-5, 10) with numpy's "negative
    dimensions"; each is a ValueError naming the canvas, before the solve."""
    class Odd(Warp):
        name = "odd"

        def _setup(self):
            self.canvas = canvas

        def forward(self, points):
            return points.copy()

    with pytest.raises(ValueError, match="odd: canvas must be"):
        warp(picture(), box(), Odd)


def test_a_plugin_that_moves_its_points_in_place_leaves_the_grid_alone():
    """``forward`` got the grid's own nodes: one that shifted them in place moved the nodes the
    fidelity check then measured against, which read a stray, took the finest grid and warned."""
    class Shifting(Warp):
        name = "shifting"

        def forward(self, points):
            points[:, 1] += 3.0 * np.sin(points[:, 0] / 10.0)       # in place, as a careless plugin does
            return points

    class Copying(Shifting):
        def forward(self, points):
            return super().forward(points.copy())

    with warnings.catch_warnings():
        warnings.simplefilter("error")                               # no stray warned
        careless, mesh = warp(picture(48, 64), box(48, 64), Shifting, return_mesh=True)
        careful, expected = warp(picture(48, 64), box(48, 64), Copying, return_mesh=True)
    np.testing.assert_array_equal(careless, careful)
    np.testing.assert_array_equal(mesh.source, expected.source)


def test_load_warp_of_no_name_says_presets_are_named_by_strings():
    """``load_warp(None)`` failed with "'NoneType' object has no attribute 'lower'" in the
    style lookup of its hint."""
    from featurewarp_cli.engine.warper import load_warp

    with pytest.raises(TypeError, match="a preset is named by a string .*swirl.*not NoneType"):
        load_warp(None)
