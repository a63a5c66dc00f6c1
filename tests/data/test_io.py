"""Tests of d3cli.data.formats: every reader/writer round trip and every bad-input message."""

from __future__ import annotations

import os

import cv2
import numpy as np
import pytest

from d3cli.data import formats as io
from d3cli.errors import InputError, OutputError


def _ramp(h=6, w=8, channels=None, dtype=np.uint8):
    top = 255 if dtype == np.uint8 else 65535
    base = np.linspace(0, top, h * w).reshape(h, w)
    if channels:
        base = np.stack([base, top - base, np.full_like(base, top // 3)][:channels] + [np.full_like(base, top)] * (channels - 3), axis=2)
    return base.astype(dtype)


# --------------------------------------------------------------------------- images


@pytest.mark.parametrize("ext", [".png", ".pgm", ".tif", ".bmp"])
def test_read_image_grey_8bit_lossless_formats(tmp_path, ext):
    grey = _ramp()
    path = tmp_path / f"g{ext}"
    cv2.imwrite(str(path), grey)
    img = io.read_image(path)
    assert img.dtype == np.uint8 and img.shape == (6, 8)
    np.testing.assert_array_equal(img, grey)


@pytest.mark.parametrize("ext", [".png", ".pgm", ".tif"])
def test_read_image_grey_16bit(tmp_path, ext):
    grey = _ramp(dtype=np.uint16)
    path = tmp_path / f"g16{ext}"
    cv2.imwrite(str(path), grey)
    img = io.read_image(path)
    assert img.dtype == np.uint16
    np.testing.assert_array_equal(img, grey)


@pytest.mark.parametrize("ext", [".png", ".ppm", ".tif"])
def test_read_image_rgb_converts_bgr_to_rgb(tmp_path, ext):
    rgb = np.zeros((4, 5, 3), np.uint8)
    rgb[..., 0] = 200  # red
    rgb[..., 2] = 10  # blue
    path = tmp_path / f"c{ext}"
    cv2.imwrite(str(path), rgb[:, :, ::-1])  # cv2 wants BGR
    img = io.read_image(path)
    assert img.shape == (4, 5, 3)
    np.testing.assert_array_equal(img, rgb)


def test_read_image_rgba_drops_alpha_and_16bit_rgb(tmp_path):
    bgra = np.dstack([np.full((3, 4), v, np.uint16) for v in (1000, 2000, 3000, 4000)])
    cv2.imwrite(str(tmp_path / "a.png"), bgra)
    img = io.read_image(tmp_path / "a.png")
    assert img.dtype == np.uint16 and img.shape == (3, 4, 3)
    assert tuple(img[0, 0]) == (3000, 2000, 1000)


def test_read_image_jpeg(tmp_path):
    rgb = np.full((16, 16, 3), (250, 128, 5), np.uint8)
    cv2.imwrite(str(tmp_path / "c.jpg"), rgb[:, :, ::-1])
    img = io.read_image(tmp_path / "c.jpg")
    assert img.shape == (16, 16, 3) and img.dtype == np.uint8
    assert np.abs(img[8, 8].astype(int) - (250, 128, 5)).max() <= 3


def test_read_image_missing_file(tmp_path):
    with pytest.raises(InputError, match=r"nope\.png: image file not found; check the path"):
        io.read_image(tmp_path / "nope.png")


@pytest.mark.parametrize("content", [b"this is not a png at all", b""])
def test_read_image_corrupt_or_empty(tmp_path, content):
    path = tmp_path / "bad.png"
    path.write_bytes(content)
    with pytest.raises(InputError) as err:
        io.read_image(path)
    message = str(err.value)
    assert message.startswith(str(path) + ": cannot read image (corrupt or not an image); ")
    assert "\n" not in message


def test_read_image_truncated_png(tmp_path):
    cv2.imwrite(str(tmp_path / "ok.png"), _ramp(40, 40))
    data = (tmp_path / "ok.png").read_bytes()
    (tmp_path / "cut.png").write_bytes(data[: len(data) // 3])
    with pytest.raises(InputError, match="cannot read image"):
        io.read_image(tmp_path / "cut.png")


def test_read_image_float_tiff_is_read_as_stored(tmp_path):
    image = np.arange(12, dtype=np.float32).reshape(3, 4) / 11
    cv2.imwrite(str(tmp_path / "f.tif"), image)
    got = io.read_image(tmp_path / "f.tif")
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, image)


def test_read_image_float_tiff_with_nan_is_an_error(tmp_path):
    cv2.imwrite(str(tmp_path / "nan.tif"), np.full((3, 3), np.nan, np.float32))
    with pytest.raises(InputError, match=r"nan\.tif: float image with NaN or inf samples"):
        io.read_image(tmp_path / "nan.tif")


def test_read_image_folder_instead_of_file(tmp_path):
    with pytest.raises(InputError, match="is a folder, not a file; give the file itself"):
        io.read_image(tmp_path)


def test_to_grey_weights_and_16bit_scale():
    rgb = np.zeros((1, 3, 3), np.uint8)
    rgb[0, 0] = (255, 0, 0)
    rgb[0, 1] = (0, 255, 0)
    rgb[0, 2] = (0, 0, 255)
    grey = io.to_grey(rgb)
    assert grey.dtype == np.float32 and grey.shape == (1, 3)
    np.testing.assert_allclose(grey[0], [0.299 * 255, 0.587 * 255, 0.114 * 255], rtol=1e-6)
    np.testing.assert_allclose(io.to_grey(np.array([[65535, 257]], np.uint16)), [[255.0, 1.0]])
    np.testing.assert_array_equal(io.to_grey(np.array([[7, 9]], np.uint8)), [[7.0, 9.0]])
    np.testing.assert_allclose(io.to_grey(np.full((1, 1, 3), 65535, np.uint16)), [[255.0]], rtol=1e-6)


def test_write_image_round_trip_rgb_and_16bit(tmp_path):
    rgb = _ramp(channels=3)
    io.write_image(tmp_path / "c.png", rgb)
    np.testing.assert_array_equal(io.read_image(tmp_path / "c.png"), rgb)
    g16 = _ramp(dtype=np.uint16)
    io.write_image(tmp_path / "g.png", g16)
    np.testing.assert_array_equal(io.read_image(tmp_path / "g.png"), g16)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.png", "g.png"]


# --------------------------------------------------------------------------- PFM

_SPECIAL = np.array(
    [[1.5, -2.25, np.inf, 0.0], [-np.inf, 3.0e-39, -0.0, 123456.789], [np.nan, 1e30, -7.0, 0.1]], np.float32
)


def _pfm_by_hand(header: bytes, rows_top_first: np.ndarray, dtype: str) -> bytes:
    return header + np.ascontiguousarray(rows_top_first[::-1], dtype=dtype).tobytes()


def test_pfm_round_trip_bit_exact(tmp_path):
    path = io.write_pfm(tmp_path / "d.pfm", _SPECIAL)
    back = io.read_pfm(path)
    assert back.dtype == np.float32 and back.shape == (3, 4)
    np.testing.assert_array_equal(back.view(np.uint32), _SPECIAL.view(np.uint32))
    data = path.read_bytes()
    assert data.startswith(b"Pf\n4 3\n-1.0\n")
    # rows are stored bottom-up: the first stored row is the last image row
    first = np.frombuffer(data, "<f4", count=4, offset=len(b"Pf\n4 3\n-1.0\n"))
    np.testing.assert_array_equal(first.view(np.uint32), _SPECIAL[2].view(np.uint32))


def test_pfm_reads_big_endian_written_by_hand(tmp_path):
    path = tmp_path / "be.pfm"
    path.write_bytes(_pfm_by_hand(b"Pf\n4 3\n1.0\n", _SPECIAL, ">f4"))
    back = io.read_pfm(path)
    np.testing.assert_array_equal(back.view(np.uint32), _SPECIAL.view(np.uint32))


def test_pfm_middlebury_scale_is_only_the_byte_order(tmp_path):
    path = tmp_path / "mb.pfm"
    values = np.array([[10.5, np.inf], [52.75, 9.0]], np.float32)
    path.write_bytes(_pfm_by_hand(b"Pf\n2 2\n-0.003922\n", values, "<f4"))
    np.testing.assert_array_equal(io.read_pfm(path), values)
    path.write_bytes(_pfm_by_hand(b"Pf\n2 2\n255.0\n", values, ">f4"))
    np.testing.assert_array_equal(io.read_pfm(path), values)


def test_pfm_three_channel(tmp_path):
    colour = np.stack([_SPECIAL, _SPECIAL * 2, -_SPECIAL], axis=2)
    path = tmp_path / "c.pfm"
    path.write_bytes(_pfm_by_hand(b"PF\n4 3\n-1\n", colour, "<f4"))
    np.testing.assert_array_equal(io.read_pfm(path).view(np.uint32), _SPECIAL.view(np.uint32))
    io.write_pfm(tmp_path / "w.pfm", colour)
    assert (tmp_path / "w.pfm").read_bytes().startswith(b"PF\n4 3\n")
    raw = io.read_pfm_raw(tmp_path / "w.pfm")
    np.testing.assert_array_equal(raw.view(np.uint32), colour.view(np.uint32))


def test_pfm_bad_header_and_truncated(tmp_path):
    (tmp_path / "x.pfm").write_bytes(b"P5\n2 2\n255\n" + bytes(4))
    with pytest.raises(InputError, match=r"x\.pfm: not a PFM file"):
        io.read_pfm(tmp_path / "x.pfm")
    (tmp_path / "t.pfm").write_bytes(b"Pf\n4 3\n-1.0\n" + bytes(20))
    with pytest.raises(InputError, match=r"truncated PFM: 4x3x1 needs 48 bytes of data, found 20"):
        io.read_pfm(tmp_path / "t.pfm")


# --------------------------------------------------------------------------- KITTI PNG


def test_kitti_png_round_trip(tmp_path):
    disp = np.array([[0.5, 10.25, np.inf], [255.99609375, 1 / 256, 100.0]], np.float32)
    io.write_kitti_png(tmp_path / "k.png", disp)
    raw = cv2.imread(str(tmp_path / "k.png"), cv2.IMREAD_UNCHANGED)
    assert raw.dtype == np.uint16
    np.testing.assert_array_equal(raw, [[128, 2624, 0], [65535, 1, 25600]])
    np.testing.assert_array_equal(io.read_kitti_png(tmp_path / "k.png"), disp)


def test_kitti_png_invalid_and_clipping():
    encoded = io.encode_kitti(np.array([[0.0, -3.0, np.nan, np.inf, 1e-4, 1e6]]))
    np.testing.assert_array_equal(encoded, [[0, 0, 0, 0, 1, 65535]])


def test_kitti_png_rejects_8bit(tmp_path):
    cv2.imwrite(str(tmp_path / "k8.png"), _ramp())
    with pytest.raises(InputError, match="KITTI disparity PNGs are 16-bit but this one is uint8"):
        io.read_kitti_png(tmp_path / "k8.png")


# --------------------------------------------------------------------------- read_disparity


def test_read_disparity_kitti_png_with_scale(tmp_path):
    raw = np.array([[0, 256, 512 + 64]], np.uint16)
    cv2.imwrite(str(tmp_path / "d.png"), raw)
    np.testing.assert_array_equal(io.read_disparity(tmp_path / "d.png", scale=256), [[np.inf, 1.0, 2.25]])


@pytest.mark.parametrize("scale", [8, 16, 4, 3])
def test_read_disparity_scaled_pgm_middlebury(tmp_path, scale):
    raw = np.array([[0, 24, 48], [255, 3, 0]], np.uint8)
    cv2.imwrite(str(tmp_path / "d.pgm"), raw)
    disp = io.read_disparity(tmp_path / "d.pgm", scale=scale)
    expected = raw.astype(np.float32) / np.float32(scale)
    expected[raw == 0] = np.inf
    np.testing.assert_array_equal(disp, expected)
    assert disp.dtype == np.float32


def test_read_disparity_npy(tmp_path):
    arr = np.array([[1.5, 0.0, np.nan], [-2.0, np.inf, 40.0]], np.float64)
    np.save(tmp_path / "d.npy", arr)
    disp = io.read_disparity(tmp_path / "d.npy")
    np.testing.assert_array_equal(disp, [[1.5, 0.0, np.inf], [-2.0, np.inf, 40.0]])  # non-finite only, as PFM
    zero = io.read_disparity(tmp_path / "d.npy", invalid="zero")
    np.testing.assert_array_equal(zero, [[1.5, np.inf, np.inf], [-2.0, np.inf, 40.0]])
    assert disp.dtype == np.float32
    none = io.read_disparity(tmp_path / "d.npy", invalid="none")
    assert none[1, 0] == -2.0 and none[0, 1] == 0.0 and np.isnan(none[0, 2])


def test_read_disparity_pfm_modes(tmp_path):
    values = np.array([[0.0, 5.0], [np.inf, np.nan]], np.float32)
    io.write_pfm(tmp_path / "d.pfm", values)
    np.testing.assert_array_equal(io.read_disparity(tmp_path / "d.pfm"), [[0.0, 5.0], [np.inf, np.inf]])
    np.testing.assert_array_equal(io.read_disparity(tmp_path / "d.pfm", invalid="zero"), [[np.inf, 5.0], [np.inf, np.inf]])
    np.testing.assert_array_equal(io.read_disparity(tmp_path / "d.pfm", invalid="0", scale=2.0), [[np.inf, 2.5], [np.inf, np.inf]])


def test_read_disparity_grey_saved_as_rgb_png(tmp_path):
    raw = np.array([[0, 30]], np.uint8)
    cv2.imwrite(str(tmp_path / "d.png"), np.dstack([raw] * 3))
    np.testing.assert_array_equal(io.read_disparity(tmp_path / "d.png", scale=3), [[np.inf, 10.0]])


def test_read_disparity_errors(tmp_path):
    (tmp_path / "d.xyz").write_bytes(b"1")
    with pytest.raises(InputError, match=r"unsupported disparity format '\.xyz'; use \.pfm, \.png, \.pgm or \.npy"):
        io.read_disparity(tmp_path / "d.xyz")
    np.save(tmp_path / "d.npy", np.ones((2, 2)))
    with pytest.raises(InputError, match="unknown invalid-value convention 'nan-ish'"):
        io.read_disparity(tmp_path / "d.npy", invalid="nan-ish")
    with pytest.raises(InputError, match="disparity scale must be > 0"):
        io.read_disparity(tmp_path / "d.npy", scale=0)
    np.save(tmp_path / "v.npy", np.ones(5))
    with pytest.raises(InputError, match="expected a 2-D real-valued disparity array"):
        io.read_disparity(tmp_path / "v.npy")
    with pytest.raises(InputError, match="disparity file not found"):
        io.read_disparity(tmp_path / "missing.pfm")


# --------------------------------------------------------------------------- masks, calib


def test_read_mask(tmp_path):
    levels = np.array([[0, 128, 255]], np.uint8)
    cv2.imwrite(str(tmp_path / "m.png"), levels)
    np.testing.assert_array_equal(io.read_mask(tmp_path / "m.png"), [[False, True, True]])
    np.testing.assert_array_equal(io.read_mask(tmp_path / "m.png", min_value=255), [[False, False, True]])
    cv2.imwrite(str(tmp_path / "c.png"), np.dstack([levels * 0, levels * 0, levels]))
    mask = io.read_mask(tmp_path / "c.png")
    assert mask.shape == (1, 3) and mask.dtype == bool
    np.testing.assert_array_equal(mask, [[False, True, True]])


MIDDLEBURY_CALIB = """cam0=[1500 0 199; 0 1500 187; 0 0 1]
cam1=[1500 0 251; 0 1500 187; 0 0 1]
doffs=52
baseline=80
width=450
height=375
ndisp=64
isint=0
vmin=12
vmax=55
"""


def test_read_calib_middlebury(tmp_path):
    (tmp_path / "calib.txt").write_text(MIDDLEBURY_CALIB)
    calib = io.read_calib(tmp_path / "calib.txt")
    assert calib == {
        "f": 1500.0, "cx": 199.0, "cy": 187.0, "doffs": 52.0, "baseline": 0.08,
        "width": 450, "height": 375, "ndisp": 64, "vmin": 12.0, "vmax": 55.0,
    }


def _p(f, cx, cy, tx):
    return f"{f:e} 0 {cx:e} {tx:e} 0 {f:e} {cy:e} 0 0 0 1 0"


def test_read_calib_kitti_2012_2015_and_karlsruhe(tmp_path):
    (tmp_path / "k12.txt").write_text(f"P0: {_p(718.856, 607.19, 185.2, 0)}\nP1: {_p(718.856, 607.19, 185.2, -386.1448)}\n"
                                      f"P2: {_p(718.856, 607.19, 185.2, 45.0)}\nP3: {_p(718.856, 607.19, 185.2, -340.0)}\n")
    calib = io.read_calib(tmp_path / "k12.txt")
    assert calib["f"] == pytest.approx(718.856) and calib["cx"] == pytest.approx(607.19)
    assert calib["baseline"] == pytest.approx(386.1448 / 718.856)
    (tmp_path / "k15.txt").write_text(f"calib_time: 09-Jan-2012 13:57:47\nP_rect_02: {_p(721.5, 609.6, 172.9, 44.86)}\n"
                                      f"P_rect_03: {_p(721.5, 609.6, 172.9, -339.57)}\n")
    assert io.read_calib(tmp_path / "k15.txt")["baseline"] == pytest.approx((44.86 + 339.57) / 721.5)
    (tmp_path / "ka.txt").write_text(f"K1: 1 0 2 0 1 3 0 0 1\nP1: {_p(645.24, 661.96, 264.13, 0)}\nP2: {_p(645.24, 661.96, 264.13, -368.2632)}\n")
    assert io.read_calib(tmp_path / "ka.txt")["baseline"] == pytest.approx(368.2632 / 645.24)


def test_read_calib_plain_key_values(tmp_path):
    (tmp_path / "c.txt").write_text("# synthetic\nf: 1000\nbaseline: 0.3\ncx=640\ncy: 360\nheight_m: 1.5\n"
                                    "pitch_deg: -5.5\nroll_deg: 1e-1\nndisp: 96\nnote: ignored\n")
    assert io.read_calib(tmp_path / "c.txt") == {
        "f": 1000.0, "baseline": 0.3, "cx": 640.0, "cy": 360.0, "height_m": 1.5,
        "pitch_deg": -5.5, "roll_deg": 0.1, "ndisp": 96,
    }


# --------------------------------------------------------------------------- output


def test_colorize_disparity_fixed_range_and_invalid_black():
    disp = np.array([[0.0, 32.0, 64.0, 100.0, np.inf, -5.0]], np.float32)
    colour = io.colorize_disparity(disp, 0, 64)
    assert colour.dtype == np.uint8 and colour.shape == (1, 6, 3)
    assert tuple(colour[0, 4]) == (0, 0, 0)
    np.testing.assert_array_equal(colour[0, 2], colour[0, 3])  # clipped at vmax
    np.testing.assert_array_equal(colour[0, 0], colour[0, 5])  # clipped at vmin
    assert not np.array_equal(colour[0, 0], colour[0, 1])


def test_atomic_write_temp_keeps_extension_and_is_renamed(tmp_path):
    seen = []

    def writer(tmp):
        seen.append(tmp)
        tmp.write_bytes(b"abc")

    final = io.atomic_write(tmp_path / "disp.png", writer)
    assert final.read_bytes() == b"abc"
    assert seen[0].parent == tmp_path and seen[0].name == f".disp.png.tmp-{os.getpid()}.png"
    assert [p.name for p in tmp_path.iterdir()] == ["disp.png"]


def test_atomic_write_failure_removes_temp_and_keeps_old(tmp_path):
    (tmp_path / "out.pfm").write_bytes(b"old")

    def failing(tmp):
        tmp.write_bytes(b"partial")
        raise RuntimeError("boom")

    with pytest.raises(RuntimeError, match="boom"):
        io.atomic_write(tmp_path / "out.pfm", failing)
    assert [p.name for p in tmp_path.iterdir()] == ["out.pfm"]
    assert (tmp_path / "out.pfm").read_bytes() == b"old"


def test_atomic_write_unwritable_folder(tmp_path):
    with pytest.raises(OutputError, match=r"missing: output folder does not exist; create it"):
        io.atomic_write(tmp_path / "missing" / "a.png", lambda tmp: tmp.write_bytes(b""))
    (tmp_path / "afile").write_bytes(b"")
    with pytest.raises(OutputError, match="output folder is a file"):
        io.atomic_write(tmp_path / "afile" / "a.png", lambda tmp: tmp.write_bytes(b""))

    def os_failure(tmp):
        raise PermissionError(13, "Permission denied")

    with pytest.raises(OutputError, match=r"a\.png: cannot write \(Permission denied\)"):
        io.atomic_write(tmp_path / "a.png", os_failure)
