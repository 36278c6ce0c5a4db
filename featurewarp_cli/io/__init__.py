"""Image files in and out: the first and the last stage of a command.

One module per step, in the order a command uses them::

    limits    the pixel limit on inputs (MAX_PIXELS), told to OpenCV's decoders too
    decode    read bytes once, check the header's size (Pillow), decode (OpenCV),
              turn upright (EXIF orientation), the mask rule
    png       PNG chunks read without decoding; a grey PNG's tRNS transparency
    colours   colour names and #rrggbb for the background
    formats   output format names, ``png:``-style prefixes, the output's format
    depth     the one rule that brings 16-bit samples to 8 bits
    encode    pixels -> file bytes with pinned settings (OpenCV's encoders)
    write     atomic writes, stdout, the writability probe
    capture   what the C decoders and encoders print on stderr, collected

``limits``, ``formats`` and ``depth`` import neither OpenCV nor Pillow, so that the
command line can use them while ``--help`` stays fast.
"""


class ImageError(Exception):
    """An image or mask that cannot be read, decoded or written."""
