"""Images beyond OpenCV's own decoder limits are refused naming the file and the fix, from
the header, instead of OpenCV's assertion text or libpng lines without a file name."""

import subprocess
import sys

import cv2
import numpy as np
import pytest

from d3cli.data import formats as io
from d3cli.errors import InputError
from tests.data.test_image_headers import _png_claiming
from tests.helpers import write_png


@pytest.mark.parametrize("width, height", [(2_000_000, 1), (1, 1_048_577)])
def test_a_side_beyond_opencvs_limit_is_refused_from_the_header(tmp_path, width, height):
    path = _png_claiming(tmp_path / "wide.png", width, height)
    with pytest.raises(InputError, match=rf"wide\.png: image of {width}x{height} pixels has a side longer than "
                                         r"1048576 pixels, the most OpenCV decodes; crop or downscale it"):
        io.read_image(path)


def test_no_libpng_or_opencv_lines_on_stderr(tmp_path):
    path = _png_claiming(tmp_path / "wide.png", 2_000_000, 1)
    code = "import sys; from d3cli.data import formats as io\ntry:\n    io.read_image(sys.argv[1])\nexcept Exception as e:\n    print(e)"
    done = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=60)
    assert "has a side longer than 1048576 pixels" in done.stdout
    assert done.stderr == ""  # was "libpng warning: Image width exceeds user limit in IHDR" and more


def test_opencv_limit_raised_by_its_variable_is_followed(tmp_path, monkeypatch):
    monkeypatch.setenv("OPENCV_IO_MAX_IMAGE_WIDTH", "100")
    write_png(tmp_path / "ok.png", np.zeros((4, 150), np.uint8))
    with pytest.raises(InputError, match="is wider than OPENCV_IO_MAX_IMAGE_WIDTH=100 "):
        io.read_image(tmp_path / "ok.png")
    monkeypatch.setenv("OPENCV_IO_MAX_IMAGE_WIDTH", "200")
    assert io.read_image(tmp_path / "ok.png").shape == (4, 150)


def test_an_opencv_assertion_names_the_file_and_the_fix(tmp_path, monkeypatch):
    """A header Pillow cannot read, which OpenCV then refuses with its assertion."""
    write_png(tmp_path / "img.png", np.zeros((4, 6), np.uint8))

    def refuse(data, flags):
        raise cv2.error("OpenCV(4.9.0) loadsave.cpp:77: error: (-215:Assertion failed) "
                        "pixels <= CV_IO_MAX_IMAGE_PIXELS in function 'validateInputImageSize'\n")

    monkeypatch.setattr(cv2, "imdecode", refuse)
    with pytest.raises(InputError) as info:
        io.read_image(tmp_path / "img.png")
    message = str(info.value)
    assert message.startswith(f"{tmp_path / 'img.png'}: cannot decode image (OpenCV: ")
    assert "validateInputImageSize" in message and message.endswith("TIFF of a sensible size")
    assert "\n" not in message
