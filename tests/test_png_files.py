"""Tests of aacmm_pin.outputs.png_files: PNG files written with zlib alone hold the pixels given.

Issue 41: Pillow's PNG writer chose a filter per row, most of writing a figure's file; the rows are
written unfiltered. Any PNG reader must read back exactly the pixels, the resolution and the text.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest

from aacmm_pin.outputs.png_files import SIGNATURE, png_bytes, write_png_file


def _chunks(data: bytes) -> list[tuple[bytes, bytes]]:
    """The (type, data) chunks of a PNG file, each CRC checked."""
    assert data[:8] == SIGNATURE
    out, at = [], 8
    while at < len(data):
        (length,) = struct.unpack(">I", data[at:at + 4])
        kind, body = data[at + 4:at + 8], data[at + 8:at + 8 + length]
        (crc,) = struct.unpack(">I", data[at + 8 + length:at + 12 + length])
        assert crc == zlib.crc32(kind + body), kind
        out.append((kind, body))
        at += 12 + length
    return out


@pytest.mark.parametrize("channels, mode", [(3, "RGB"), (4, "RGBA")])
def test_pillow_reads_back_the_pixels_resolution_and_text(tmp_path, channels, mode):
    """Random pixels (nothing for zlib to find), RGB and RGBA, and a view with strides (the RGB of
    an RGBA buffer): Pillow reads the same array, mode, dpi and Software text back."""
    from PIL import Image

    rgba = np.random.default_rng(0).integers(0, 256, (37, 53, 4), dtype=np.uint8)
    pixels = rgba[..., :channels]
    path = write_png_file(pixels, tmp_path / "p.png", 120.0, "Matplotlib version3, x")
    with Image.open(path) as image:
        assert image.mode == mode and image.size == (53, 37)
        assert np.array_equal(np.asarray(image), pixels)
        assert image.info["dpi"] == pytest.approx((120.0, 120.0), abs=0.05)
        assert image.info["Software"] == "Matplotlib version3, x"


def test_the_file_is_well_formed_and_its_rows_unfiltered():
    """Chunks in PNG's order (IHDR first, pHYs before the data, IEND last), CRCs right, every
    row's filter byte 0, the rows the pixels; no text chunk when no software is named."""
    pixels = np.zeros((4, 5, 3), np.uint8)
    pixels[1, 2] = (255, 0, 7)
    chunks = _chunks(png_bytes(pixels, 150.0))
    assert [kind for kind, _ in chunks] == [b"IHDR", b"pHYs", b"IDAT", b"IEND"]
    assert struct.unpack(">IIBBBBB", chunks[0][1]) == (5, 4, 8, 2, 0, 0, 0)
    assert struct.unpack(">IIB", chunks[1][1]) == (5906, 5906, 1)  # 150 dpi in px per m
    rows = np.frombuffer(zlib.decompress(chunks[2][1]), np.uint8).reshape(4, 16)
    assert np.all(rows[:, 0] == 0)
    assert np.array_equal(rows[:, 1:].reshape(4, 5, 3), pixels)
