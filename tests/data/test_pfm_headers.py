"""PFM headers as other tools write them: CRLF line ends, and a scale of 0 (refused)."""

import numpy as np
import pytest

from d3cli.data import formats as io
from d3cli.errors import InputError


def _pfm(header: bytes, values: np.ndarray) -> bytes:
    return header + np.ascontiguousarray(values[::-1], dtype="<f4").tobytes()


@pytest.mark.parametrize("newline", [b"\n", b"\r\n"])
def test_pfm_with_lf_or_crlf_header_reads_the_same_values(tmp_path, newline):
    disp = np.arange(12, dtype=np.float32).reshape(3, 4) + 0.25
    path = tmp_path / "d.pfm"
    path.write_bytes(_pfm(b"Pf" + newline + b"4 3" + newline + b"-1.0" + newline, disp))
    np.testing.assert_array_equal(io.read_pfm(path), disp)


def test_pfm_raster_starting_with_a_newline_byte_is_not_taken_for_crlf(tmp_path):
    # little-endian float whose first byte is 0x0A, after a CR-terminated... LF header
    disp = np.full((2, 2), np.frombuffer(b"\n\x00\x80\x3f", "<f4")[0], np.float32)
    path = tmp_path / "d.pfm"
    path.write_bytes(_pfm(b"Pf\n2 2\n-1\r", disp))  # header ends with a lone CR
    np.testing.assert_array_equal(io.read_pfm(path), disp)


@pytest.mark.parametrize("scale", [b"0", b"0.0", b"-0"])
def test_pfm_scale_zero_is_an_error_naming_the_file(tmp_path, scale):
    path = tmp_path / "zero.pfm"
    path.write_bytes(_pfm(b"Pf\n2 2\n" + scale + b"\n", np.ones((2, 2), np.float32)))
    with pytest.raises(InputError, match=r"zero\.pfm: PFM scale is 0, so the byte order is unknown; write the file"):
        io.read_pfm(path)
