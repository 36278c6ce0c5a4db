"""compare's panel: labels that tell the views apart at any size, and the input's profile kept."""

import cv2
import numpy as np
import pytest
from PIL import Image, ImageCms

from featurewarp_cli.app import panel
from samples import scenes
from test_cli import Runner

VIEWS = [panel.LABELS["input + mask"]] + [tuple(form.format(preset="swirl") for form in panel.LABELS[mode])
                                         for mode in ("plain", "rigid", "similarity")]


def width_of(text: str, font: float) -> int:
    return cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, font, 1)[0][0]


@pytest.mark.parametrize("across,height", [(60, 2000), (150, 170), (24, 300), (9, 40)])
def test_narrow_views_get_short_labels_that_fit_and_differ(across, height):
    """A 600 px panel read "featurewarp rigi" | "featurewarp sim", a tall one "featur" | "featur"."""
    labels, font = panel.fit_labels(VIEWS, [across] * 4, height)
    assert len(set(labels)) == 4, labels
    if across >= 24:
        assert all(width_of(text, font) <= across for text in labels), (labels, font)
    assert font >= panel.SMALLEST_FONT


def test_wide_views_keep_their_full_labels_and_tall_ones_a_larger_font():
    """The gallery's panels keep their labels; a 12 MP view's were a few hundredths of its height."""
    labels, font = panel.fit_labels(VIEWS, [512] * 4, 512)
    assert labels == ["input + mask", "plain swirl", "featurewarp rigid", "featurewarp similarity"]
    assert font == panel.FONT
    labels, font = panel.fit_labels(VIEWS, [4000] * 4, 3000)
    assert font > 2 and labels[3] == "featurewarp similarity"
    assert panel.panel_size([(300, 1500)] * 4) == panel.labelled_panel(
        [np.zeros((1500, 300, 3), np.uint8)] * 4, VIEWS).shape[1::-1]            # its larger caption bar


def test_compare_keeps_the_inputs_profile_unless_strip(tmp_path):
    """The panel dropped the input's ICC profile though --strip's help says it is kept."""
    profile = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()
    image, mask = scenes.scene()
    Image.fromarray(image[::2, ::2, ::-1]).save(tmp_path / "in.png", icc_profile=profile)
    cv2.imwrite(str(tmp_path / "mask.png"), mask[::2, ::2].astype(np.uint8) * 255)
    for name, extra in (("p.png", []), ("s.png", ["--strip"])):
        run = Runner()("compare", "swirl", str(tmp_path / "in.png"), str(tmp_path / name), "-m",
                       str(tmp_path / "mask.png"), *extra)
        assert run.code == 0, run.stderr
    with Image.open(tmp_path / "p.png") as kept, Image.open(tmp_path / "s.png") as stripped:
        assert kept.info.get("icc_profile") == profile and not stripped.info.get("icc_profile")


def test_compare_of_a_16_bit_input_says_its_panel_has_8_bits(tmp_path):
    """The panel is 8-bit (its labels and tints); a 16-bit input's depth was dropped silently."""
    image, mask = scenes.scene()
    cv2.imwrite(str(tmp_path / "in.png"), image[::2, ::2].astype(np.uint16) * 257)
    cv2.imwrite(str(tmp_path / "mask.png"), mask[::2, ::2].astype(np.uint8) * 255)
    run = Runner()("compare", "swirl", str(tmp_path / "in.png"), str(tmp_path / "p.png"), "-m", str(tmp_path / "mask.png"))
    assert run.code == 0 and "the comparison panel has 8" in run.stderr
    assert cv2.imread(str(tmp_path / "p.png"), cv2.IMREAD_UNCHANGED).dtype == np.uint8
