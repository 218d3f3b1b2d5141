"""physrelight.io.write_png: lossless at the chosen zlib level."""

import numpy as np
from PIL import Image

from physrelight import io


def test_01_png_is_lossless_at_the_chosen_level(tmp_path):
    rng = np.random.default_rng(0)
    u8 = rng.integers(0, 256, size=(37, 53, 3), dtype=np.uint8)
    path = tmp_path / "x.png"
    io.write_png(path, u8.astype(np.float32) / 255.0)
    np.testing.assert_array_equal(np.asarray(Image.open(path)), u8)
    assert io.PNG_COMPRESS_LEVEL == 1
    assert not [p for p in tmp_path.iterdir() if p.name != "x.png"]  # no debris
