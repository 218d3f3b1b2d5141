"""physrelight.io.write_png and physrelight.png.encode_png: lossless, a valid PNG that Pillow and zlib read back
(CRCs and the Adler-32 checked), the same bytes at any thread count, clear errors."""

import struct
import zlib

import numpy as np
import pytest
import torch
from PIL import Image

from physrelight import io
from physrelight.png import STRIP_ROWS, encode_png


def test_01_png_is_lossless_at_the_chosen_level(tmp_path):
    rng = np.random.default_rng(0)
    u8 = rng.integers(0, 256, size=(37, 53, 3), dtype=np.uint8)
    path = tmp_path / "x.png"
    io.write_png(path, u8.astype(np.float32) / 255.0)
    np.testing.assert_array_equal(np.asarray(Image.open(path)), u8)
    assert io.PNG_COMPRESS_LEVEL == 1
    assert not [p for p in tmp_path.iterdir() if p.name != "x.png"]  # no debris


def _chunks(data: bytes) -> list[tuple[bytes, bytes]]:
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    out, pos = [], 8
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos: pos + 4])
        kind, body = data[pos + 4: pos + 8], data[pos + 8: pos + 8 + n]
        assert struct.unpack(">I", data[pos + 8 + n: pos + 12 + n])[0] == zlib.crc32(kind + body)
        out.append((kind, body))
        pos += 12 + n
    return out


@pytest.mark.parametrize("shape", [(1, 1), (1, 700, 3), (700, 1, 3), (2 * STRIP_ROWS + 5, 31, 4), (129, 64, 2),
                                   (300, 41, 1), (3, 5)])
@pytest.mark.parametrize("level", [0, 1, 6, 9])
def test_02_every_colour_type_and_size_reads_back_exactly_with_valid_checksums(shape, level):
    """Strips of STRIP_ROWS rows joined into one zlib stream: Pillow decodes it (checking every CRC), zlib's own
    decompressor accepts the stream and its Adler-32, and the rows are the image Paeth-filtered."""
    rng = np.random.default_rng(sum(shape))
    u8 = rng.integers(0, 256, size=shape, dtype=np.uint8)
    u8[: shape[0] // 2] //= 16  # some structure for the filter and the compressor
    data = encode_png(u8, level)
    got = np.asarray(Image.open(__import__("io").BytesIO(data)))
    np.testing.assert_array_equal(got.reshape(u8.shape), u8)
    chunks = _chunks(data)
    assert [k for k, _ in chunks][0] == b"IHDR" and chunks[-1][0] == b"IEND"
    raw = zlib.decompress(b"".join(b for k, b in chunks if k == b"IDAT"))  # checks the header and the Adler-32
    c = 1 if u8.ndim == 2 else u8.shape[-1]
    rows = np.frombuffer(raw, dtype=np.uint8).reshape(shape[0], shape[1] * c + 1)
    assert (rows[:, 0] == 4).all()


def test_03_the_bytes_do_not_depend_on_the_thread_count():
    rng = np.random.default_rng(3)
    u8 = rng.integers(0, 256, size=(3 * STRIP_ROWS + 7, 90, 3), dtype=np.uint8)
    before = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        one = encode_png(u8)
        torch.set_num_threads(2)
        two = encode_png(u8)
    finally:
        torch.set_num_threads(before)
    assert one == two


def test_04_the_paeth_filter_is_the_specifications():
    """Every filtered byte against the PNG specification's Paeth predictor written out in Python."""
    rng = np.random.default_rng(4)
    u8 = rng.integers(0, 256, size=(6, 5, 3), dtype=np.uint8)
    chunks = _chunks(encode_png(u8))
    rows = np.frombuffer(zlib.decompress(b"".join(b for k, b in chunks if k == b"IDAT")), np.uint8).reshape(6, 16)
    img = u8.reshape(6, 15).astype(int)
    for i in range(6):
        for k in range(15):
            a = img[i, k - 3] if k >= 3 else 0
            b = img[i - 1, k] if i > 0 else 0
            c = img[i - 1, k - 3] if i > 0 and k >= 3 else 0
            p = a + b - c
            pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
            pred = a if pa <= pb and pa <= pc else b if pb <= pc else c
            assert rows[i, k + 1] == (img[i, k] - pred) % 256


def test_05_a_stream_longer_than_one_chunk_is_split_over_several_idat_chunks(monkeypatch):
    from physrelight import png

    monkeypatch.setattr(png, "IDAT_BYTES", 1000)
    rng = np.random.default_rng(5)
    u8 = rng.integers(0, 256, size=(200, 50, 3), dtype=np.uint8)  # noise: about 30 kB compressed
    data = encode_png(u8)
    idats = [b for k, b in _chunks(data) if k == b"IDAT"]
    assert len(idats) > 10 and all(len(b) <= 1000 for b in idats)
    np.testing.assert_array_equal(np.asarray(Image.open(__import__("io").BytesIO(data))), u8)


def test_06_bad_input_is_named():
    with pytest.raises(ValueError, match="uint8"):
        encode_png(np.zeros((4, 4, 3), dtype=np.float32))
    with pytest.raises(ValueError, match="C in 1-4"):
        encode_png(np.zeros((4, 4, 5), dtype=np.uint8))
    with pytest.raises(ValueError, match="C in 1-4"):
        encode_png(np.zeros((0, 4, 3), dtype=np.uint8))
    with pytest.raises(ValueError, match="level"):
        encode_png(np.zeros((4, 4, 3), dtype=np.uint8), 10)
