"""Image sizes come from the headers before anything is decoded, so a huge or broken file is refused without being decoded."""

import struct
import zlib

import numpy as np
import pytest

from d3cli.data import formats as io
from d3cli.data.layouts import load_pair_images, pair_image_size, read_pair_folder
from d3cli.errors import InputError
from tests.helpers import write_png


def _png_claiming(path, width, height):
    """A tiny PNG whose header claims width x height 8-bit grey pixels."""
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 64))
                     + chunk(b"IEND", b""))
    return path


def test_image_size_reads_only_the_header(tmp_path):
    assert io.image_size(_png_claiming(tmp_path / "big.png", 32000, 32000)) == (32000, 32000)
    write_png(tmp_path / "small.png", np.zeros((5, 7), np.uint8))
    assert io.image_size(tmp_path / "small.png") == (7, 5)
    (tmp_path / "junk.png").write_bytes(b"not an image")
    assert io.image_size(tmp_path / "junk.png") is None


def test_a_huge_header_is_refused_before_decoding(tmp_path):
    path = _png_claiming(tmp_path / "bomb.png", 32000, 32000)
    with pytest.raises(InputError, match=r"bomb\.png: image of 32000x32000 pixels is larger than 268435456 pixels "
                                         r"\(about 6\.1 GB to decode\); give an image of at most 16384x16384"):
        io.read_image(path)


def test_pair_sizes_from_headers_and_mismatch_refused_before_decoding(tmp_path):
    folder = tmp_path / "p"
    folder.mkdir()
    write_png(folder / "left.png", np.zeros((6, 10), np.uint8))
    _png_claiming(folder / "right.png", 20000, 20000)
    pair = read_pair_folder(folder)
    assert pair_image_size(pair) == (6, 10)
    with pytest.raises(InputError, match=r"p: left is 6x10 but right is 20000x20000; a stereo pair needs equal sizes"):
        load_pair_images(pair)


def test_a_truncated_png_gives_our_error_and_no_opencv_warning(tmp_path):
    import subprocess
    import sys

    write_png(tmp_path / "ok.png", (np.arange(2500) % 251).astype(np.uint8).reshape(50, 50))
    data = (tmp_path / "ok.png").read_bytes()
    (tmp_path / "cut.png").write_bytes(data[: len(data) // 2])
    code = "import sys; from d3cli.data import formats as io\ntry:\n    io.read_image(sys.argv[1])\nexcept Exception as e:\n    print(e)"
    done = subprocess.run([sys.executable, "-c", code, str(tmp_path / "cut.png")], capture_output=True, text=True,
                          timeout=60)
    assert "cannot read image (corrupt or not an image)" in done.stdout
    assert "WARN" not in done.stderr, done.stderr
