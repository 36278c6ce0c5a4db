"""Regenerate the sample feature masks and the synthetic test image.

Run ``python samples/make_masks.py`` (from anywhere) to rewrite, next to this file:

* ``astronaut_mask.png`` and ``coins_mask.png``: rough, lasso-like selections for the
  two photos (hard-coded polygon vertices below, in pixel coordinates x,y; the coins'
  polygons trimmed apart where two face each other, :func:`separated`);
* ``astronaut_body_mask.png``: a loose lasso of the astronaut's head and body, one
  component that runs out of the bottom and the left edge (a portrait cut by the frame);
* ``astronaut_helmet_mask.png``: the head (as in ``astronaut_mask.png``) and the helmet
  she holds, which runs out of the bottom and the right edge: a head + object mask
  covering 22 % of the frame (``make bench`` upscales it to 12 MP, a hard case for
  the fold-over guard);
* ``closeup.png`` and ``closeup_mask.png``: a tight crop of the astronaut's head,
  upscaled 2x, and a lasso of head and shoulders covering about 80 % of it (a close-up
  whose subject fills the frame and touches three sides);
* ``shapes.png`` and ``shapes_mask.png``: a 640x480 synthetic image with six solid
  shapes on a textured gray background, and its mask (the shapes dilated by ~6 px),
  drawn by ``scenes.py``, the synthetic scene generator the tests and benchmarks use;
* ``china_mask.png``: two loose lassos on scikit-learn's ``china.jpg`` (``china.png``
  here): the pagoda, inside the frame, and the clump of trees on the right, which runs
  out of the bottom and the right edge; trimmed 12 px apart (:func:`separated`) so they
  stay two features (44 % of the frame);
* ``dahlia.png`` and ``dahlia_mask.png``: a crop of scikit-learn's ``flower.jpg``
  around the dahlia, upscaled 2x, which cuts the flower at the top and the right edge,
  and a lasso of the flower (80 % of the frame).

``china.png`` and ``dahlia.png`` are rebuilt only when scikit-learn's sample photos are
found: ``python samples/make_masks.py DIR`` with DIR the folder holding ``china.jpg``
and ``flower.jpg`` (``sklearn/datasets/images`` in its wheel), or scikit-learn
installed; otherwise the committed PNGs are kept and only their masks are redrawn.

Masks are single-channel 8-bit PNGs, 255 = feature, 0 = background. The output is
deterministic (the background noise uses a fixed seed). Needs only numpy and cv2.
"""
import importlib.util
import sys
from pathlib import Path

import cv2
import numpy as np
from scenes import sample_scene       # scenes.py, beside this file

HERE = Path(__file__).resolve().parent

# Astronaut (512x512): head with hair, mission patch, space-shuttle model.
ASTRONAUT = [
    # head and hair
    [222,8, 248,9, 272,16, 292,30, 304,48, 309,70, 307,92, 302,112, 290,126, 278,136,
     272,152, 262,170, 248,184, 226,192, 204,186, 190,172, 180,152, 172,136, 160,126,
     150,110, 146,88, 147,64, 153,42, 166,25, 186,13, 204,9],
    # round mission patch on the chest
    [212,389, 209,403, 202,417, 189,425, 174,426, 159,426, 146,420, 137,408, 128,396,
     130,381, 132,366, 141,354, 153,346, 168,341, 183,342, 197,348, 206,361, 214,374],
    # shuttle model on its stand (the tank reaches the top edge of the photo)
    [402,3, 428,3, 442,18, 446,34, 455,38, 462,50, 463,120, 464,200, 464,230, 466,262,
     466,292, 440,295, 404,295, 368,294, 362,262, 360,236, 348,230, 346,214, 354,200,
     370,182, 376,160, 376,112, 378,90, 378,60, 381,42, 386,34, 393,36, 398,22],
]

# Astronaut (512x512), head and body in one loose lasso: around the hair, the helmet
# ring and the suit's right shoulder, along the top and left rim of the helmet she
# holds (it stays out), out of the bottom edge, and up the left edge past the flag,
# which her left arm almost touches.
ASTRONAUT_BODY = [
    [222,8, 248,9, 272,16, 292,30, 304,48, 309,70, 307,92, 302,112, 292,128, 284,142,
     296,156, 306,176, 311,200, 312,226, 320,238, 338,246, 352,262, 362,286, 368,312,
     373,336, 352,352, 330,372, 306,384, 294,404, 288,440, 285,480, 284,512,
     0,512, 0,372, 10,344, 18,316, 30,288, 44,264, 62,246, 88,234, 108,224,
     108,200, 114,176, 128,156, 146,142, 156,126,
     150,110, 146,88, 147,64, 153,42, 166,25, 186,13, 204,9],
]

# Astronaut (512x512): the helmet she holds, around its top and left rim, out of the
# bottom edge and back in along the right edge (its strap touches it).
HELMET = [
    [284,512, 281,470, 285,432, 296,400, 314,374, 340,356, 376,344, 420,340, 458,346,
     486,364, 502,390, 510,418, 512,436, 512,512],
]

# Close-up: astronaut.png[y0:y0+h, x0:x0+w] upscaled 2x (bicubic) to 332x392.
CLOSEUP_CROP = (140, 8, 166, 196)       # x0, y0, w, h in astronaut.png
# Head and shoulders in closeup.png's pixels: the hair (touching the right edge),
# the right cheek and neck down to the suit's ring, out of the bottom edge, across
# the ring to the left edge, and up the neck and the hair's left side.
CLOSEUP = [
    [174,4, 212,6, 246,16, 274,32, 298,54, 316,82, 328,112, 332,140, 332,186, 324,216,
     302,240, 286,262, 280,292, 274,316, 292,334, 306,360, 318,392,
     0,392, 0,272, 26,266, 58,264, 80,258,
     74,240, 52,228, 32,202, 20,172, 16,140, 22,104, 36,74, 60,48, 90,28, 122,12, 148,6],
]

# Coins (384x303): one loose polygon per coin, in reading order (4 rows of 6). Traced
# once from a threshold + contour pass, sampled every ~20 degrees a few pixels outside
# the coin's edge with slight jitter, then frozen here; neighbours come within 3 px, so
# the mask trims them apart (:func:`separated`).
COINS = [
    [62,39, 67,46, 70,55, 67,64, 60,70, 54,76, 46,78, 38,77, 30,74, 23,69, 21,60, 18,51,
     23,43, 30,38, 37,35, 45,35, 55,33],
    [81,44, 87,38, 95,35, 104,36, 112,38, 119,43, 123,51, 123,60, 121,70, 114,75, 105,78,
     97,77, 88,76, 81,70, 78,61, 75,52],
    [178,35, 181,43, 182,52, 183,61, 175,67, 170,75, 162,77, 153,78, 145,75, 138,70,
     131,64, 128,55, 127,46, 132,38, 136,30, 145,27, 154,25, 163,24, 170,29],
    [238,36, 241,46, 242,55, 240,65, 233,72, 223,75, 214,78, 205,76, 196,71, 190,63,
     188,53, 190,43, 196,36, 202,28, 212,26, 221,26, 231,29],
    [277,33, 284,33, 290,36, 295,42, 299,48, 300,55, 297,62, 294,68, 288,73, 280,74,
     274,73, 267,71, 261,68, 256,62, 254,55, 254,47, 261,42, 264,35, 270,33],
    [352,71, 341,73, 331,73, 320,71, 312,65, 304,56, 302,45, 304,34, 309,24, 318,18,
     328,14, 339,14, 350,15, 358,23, 364,32, 366,42, 366,54, 360,63],
    [54,102, 62,106, 69,113, 69,123, 69,132, 65,140, 58,146, 49,149, 40,149, 32,145,
     24,140, 21,131, 21,122, 22,113, 29,106, 37,102, 45,100],
    [123,119, 125,127, 122,134, 117,139, 112,144, 105,147, 98,147, 91,144, 84,139, 82,132,
     80,125, 84,118, 87,112, 93,108, 99,103, 107,106, 114,107, 120,112],
    [138,111, 147,109, 154,108, 161,110, 169,113, 174,120, 177,128, 174,137, 167,142,
     161,146, 153,146, 145,146, 138,142, 133,135, 129,127, 134,118],
    [188,106, 196,104, 204,102, 212,101, 220,103, 227,109, 231,117, 228,126, 228,135,
     222,141, 216,147, 207,149, 198,149, 192,143, 186,137, 183,129, 181,121, 184,114],
    [245,107, 249,99, 258,95, 266,91, 275,93, 285,93, 294,98, 298,107, 302,117, 300,127,
     295,135, 288,141, 280,147, 271,146, 261,146, 252,143, 244,136, 242,126, 241,116],
    [327,145, 317,141, 312,132, 313,122, 314,112, 322,104, 331,102, 341,100, 351,104,
     357,113, 360,122, 359,132, 354,141, 345,146, 336,149],
    [55,175, 61,183, 66,191, 68,201, 65,211, 56,216, 47,218, 38,220, 29,215, 23,208,
     19,199, 22,189, 28,182, 35,176, 45,174],
    [122,210, 115,216, 108,220, 99,220, 91,217, 84,212, 78,206, 78,197, 79,189, 82,181,
     88,175, 96,173, 105,171, 113,173, 119,179, 124,186, 128,194, 125,202],
    [169,213, 163,219, 154,218, 146,219, 139,215, 134,208, 133,200, 132,192, 136,184,
     143,179, 150,175, 158,177, 166,178, 173,183, 177,191, 178,200, 175,208],
    [239,205, 233,215, 221,219, 210,220, 199,217, 190,210, 183,200, 186,188, 190,177,
     198,169, 209,165, 221,166, 232,171, 240,181, 242,193],
    [254,209, 247,200, 246,189, 250,178, 259,170, 270,167, 281,169, 290,175, 296,183,
     302,193, 299,204, 293,214, 284,221, 272,219, 262,215],
    [365,154, 373,163, 379,173, 383,185, 383,198, 375,208, 366,216, 354,220, 342,220,
     332,213, 322,207, 313,198, 311,186, 314,174, 320,163, 330,157, 341,152, 353,152],
    [53,292, 41,291, 30,287, 22,279, 16,269, 15,258, 16,245, 25,237, 35,232, 46,227,
     58,229, 69,234, 75,245, 78,256, 77,268, 71,278, 63,285],
    [90,265, 92,257, 95,250, 101,245, 108,243, 116,241, 124,244, 130,248, 135,255, 138,262,
     139,270, 136,278, 129,283, 124,290, 115,290, 108,287, 101,284, 95,280, 89,274],
    [176,291, 167,288, 158,286, 149,280, 142,273, 142,262, 143,252, 148,244, 156,239,
     165,235, 174,233, 183,233, 192,238, 200,245, 204,255, 204,265, 201,275, 194,283,
     185,288],
    [236,286, 228,284, 223,277, 216,270, 216,261, 220,253, 224,245, 232,242, 240,238,
     248,239, 257,238, 263,245, 269,252, 270,261, 270,270, 266,277, 260,283, 253,289,
     244,289],
    [291,238, 302,237, 312,237, 321,244, 327,253, 328,264, 323,273, 319,283, 310,287,
     300,291, 289,288, 280,282, 274,273, 273,262, 275,252, 284,245],
    [336,259, 340,251, 349,249, 357,245, 365,245, 373,249, 378,256, 383,264, 381,273,
     378,281, 372,288, 364,290, 355,291, 347,289, 340,284, 335,276, 331,267],
]

# China (scikit-learn's china.jpg, 640x427, as china.png): the pagoda from the finial to
# its lowest roof (the trees in front of its base stay out), and the clump of trees right
# of it, from the tall tree's crown down the lake shore and around the pagoda's lowest
# roof, out of the bottom edge and back up the right edge. Traced once from a colour
# threshold (the pagoda: what is not pale sky; the trees: dark or saturated pixels),
# closed, dilated a few pixels and simplified (2 px), then frozen here and corrected by
# hand where the threshold ran into the lake.
CHINA = [
    [199,27, 193,32, 194,47, 189,55, 189,62, 175,76, 137,97, 129,99, 123,94, 110,103, 94,105,
     90,131, 111,143, 116,155, 100,164, 83,167, 80,184, 94,194, 95,225, 92,238, 78,244, 66,250,
     57,262, 58,278, 66,277, 77,282, 73,294, 67,300, 76,304, 82,330, 148,333, 158,350, 190,355,
     193,374, 204,395, 285,397, 321,393, 365,371, 381,355, 385,337, 366,320, 350,316, 348,292,
     343,285, 344,267, 355,258, 353,247, 329,235, 330,224, 322,221, 321,188, 333,179, 331,170,
     324,166, 316,166, 305,158, 300,160, 296,156, 297,141, 323,126, 321,116, 306,113, 294,103,
     287,106, 282,101, 243,84, 219,63, 219,55, 215,49, 218,29],
    [640,158, 626,151, 623,143, 611,136, 606,138, 599,135, 585,145, 583,156, 571,178, 572,193,
     565,203, 552,210, 544,221, 546,243, 549,247, 546,267, 527,274, 510,293, 494,300, 487,300,
     483,294, 471,291, 458,295, 453,301, 414,311, 397,321, 390,322, 394,339, 389,359, 366,381,
     328,399, 328,427, 640,427],
]
#: The pagoda and the trees come within a few pixels under its lowest roof, where they face
#: each other diagonally: trimmed apart as the coins are, but by more than 8 * sqrt(2) px, so
#: that no two of their 4 px grid cells touch even at a corner and each is a feature of its
#: own (at 9 px, as for the coins, the engine's 8-connected cells joined them into one).
CHINA_GAP = 13

# Dahlia: scikit-learn's flower.jpg[y0:y0+h, x0:x0+w] upscaled 2x (bicubic) to 500x480;
# the flower (x 169-446, y 85-360 in flower.jpg) runs out of the top and the right edge.
DAHLIA_CROP = (150, 130, 250, 240)      # x0, y0, w, h in flower.jpg
# The flower in dahlia.png's pixels, a few pixels outside its petals: traced once from an
# orange threshold (hue < 30, saturation > 60, value > 110), dilated 3 px, simplified
# (3 px) and frozen; it leaves the frame along the top and the right edge.
DAHLIA = [
    [78,20, 68,42, 70,69, 58,74, 46,90, 50,125, 36,136, 32,146, 32,201, 42,220, 36,232, 40,269,
     52,284, 52,295, 62,308, 70,335, 88,352, 96,373, 142,413, 163,421, 174,435, 198,449, 225,445,
     280,465, 305,465, 324,457, 340,463, 371,461, 392,449, 419,445, 443,435, 472,413, 500,405,
     500,0, 102,0, 99,8],
]


def polygon_mask(shape, polygons):
    """Fill flat [x0,y0, x1,y1, ...] polygons into a uint8 mask of the given (h, w)."""
    mask = np.zeros(shape[:2], np.uint8)
    pts = [np.array(p, np.int32).reshape(-1, 1, 2) for p in polygons]
    cv2.fillPoly(mask, pts, 255)
    return mask


#: Least distance between two coins' polygons in the mask, px: the polygons come within 3 to
#: 5 px of each other, under one 4 px grid cell, and there neighbouring coins share grid cells
#: and become one feature: a row of four coins moves as one rigid piece, which no bend can
#: carry (issue 25 item 6). 9 leaves every two coins at least 8 px (two cells) apart, each its
#: own feature, trimming a polygon only where it faces a close neighbour (the coins
#: themselves are 8 to 19 px apart: 41 pixels of their rims, at most 2 px deep, are left out).
COIN_GAP = 9


def separated(shape, polygons, gap):
    """Fill each polygon, trimmed where it faces another, so that no two come within ``gap``
    px: a pixel of one stays when its distance to the nearest other polygon plus its depth in
    its own is at least ``gap`` (each of two close polygons gives up half the shortfall)."""
    fills = [polygon_mask(shape, [p]) > 0 for p in polygons]
    away = [cv2.distanceTransform((~f).view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE) for f in fills]
    mask = np.zeros(shape[:2], np.uint8)
    for k, fill in enumerate(fills):
        others = np.min([a for j, a in enumerate(away) if j != k], axis=0)
        depth = cv2.distanceTransform(fill.view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        mask[fill & (others + depth >= gap)] = 255
    return mask


def make_closeup(astronaut):
    """Return the close-up: :data:`CLOSEUP_CROP` of ``astronaut`` upscaled 2x (bicubic)."""
    x0, y0, w, h = CLOSEUP_CROP
    return cv2.resize(astronaut[y0:y0 + h, x0:x0 + w], (2 * w, 2 * h), interpolation=cv2.INTER_CUBIC)


def make_dahlia(flower):
    """Return the dahlia: :data:`DAHLIA_CROP` of ``flower`` upscaled 2x (bicubic)."""
    x0, y0, w, h = DAHLIA_CROP
    return cv2.resize(flower[y0:y0 + h, x0:x0 + w], (2 * w, 2 * h), interpolation=cv2.INTER_CUBIC)


def sklearn_images(argv):
    """The folder of scikit-learn's sample photos: ``argv[0]`` if given, else the installed
    package's ``datasets/images`` (found without importing it), else None."""
    if argv:
        return Path(argv[0])
    spec = importlib.util.find_spec("sklearn")
    folder = spec and spec.origin and Path(spec.origin).parent / "datasets" / "images"
    return folder if folder and (folder / "china.jpg").exists() else None


def main(argv=()):
    cv2.imwrite(str(HERE / "closeup.png"), make_closeup(cv2.imread(str(HERE / "astronaut.png"))))
    folder = sklearn_images(list(argv))
    if folder is not None:
        for name, photo in (("china", cv2.imread(str(folder / "china.jpg"))),
                            ("dahlia", make_dahlia(cv2.imread(str(folder / "flower.jpg"))))):
            if photo is None:
                raise SystemExit(f"no china.jpg / flower.jpg in {folder}")
            cv2.imwrite(str(HERE / f"{name}.png"), photo)
    gaps = {"coins": COIN_GAP, "china": CHINA_GAP}
    for name, polygons in (("astronaut", ASTRONAUT), ("astronaut_body", ASTRONAUT_BODY),
                           ("astronaut_helmet", ASTRONAUT[:1] + HELMET),
                           ("coins", COINS),
                           ("coins_whole", [p for p in COINS if max(p[0::2]) < 383]),
                           ("closeup", CLOSEUP), ("china", CHINA), ("dahlia", DAHLIA)):
        photo = cv2.imread(str(HERE / f"{name.split('_')[0]}.png"), cv2.IMREAD_UNCHANGED)
        gap = gaps.get(name.split("_")[0])
        mask = separated(photo.shape, polygons, gap) if gap else polygon_mask(photo.shape, polygons)
        cv2.imwrite(str(HERE / f"{name}_mask.png"), mask)
    img, mask = sample_scene()
    cv2.imwrite(str(HERE / "shapes.png"), img)
    cv2.imwrite(str(HERE / "shapes_mask.png"), mask.astype(np.uint8) * 255)


if __name__ == "__main__":
    main(sys.argv[1:])
