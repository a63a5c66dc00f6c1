"""Karlsruhe calibration files describe the full and the cropped (roi) images; the
images are distributed cropped, so the roi projections apply."""

from d3cli.data.formats import read_calib

CALIB = """\
roi: 2.6e+01 1.369e+03 7.0e+01 4.41e+02
P1: 6.452401e+02 0 6.619587e+02 0 0 6.452401e+02 2.641291e+02 0 0 0 1 0
P1_roi: 6.452401e+02 0 6.359587e+02 0 0 6.452401e+02 1.941291e+02 0 0 0 1 0
P2: 6.452401e+02 0 6.619587e+02 -3.682632e+02 0 6.452401e+02 2.641291e+02 0 0 0 1 0
P2_roi: 6.452401e+02 0 6.359587e+02 -3.682632e+02 0 6.452401e+02 1.941291e+02 0 0 0 1 0
"""


def test_roi_projection_for_cropped_images(tmp_path):
    path = tmp_path / "calib.txt"
    path.write_text(CALIB)
    for size in (None, (1344, 372)):
        calib = read_calib(path, image_size=size)
        assert (calib["cx"], calib["cy"]) == (635.9587, 194.1291)
        assert abs(calib["baseline"] - 368.2632 / 645.2401) < 1e-9 and calib["f"] == 645.2401


def test_full_projection_for_uncropped_images(tmp_path):
    path = tmp_path / "calib.txt"
    path.write_text(CALIB)
    calib = read_calib(path, image_size=(1392, 512))
    assert (calib["cx"], calib["cy"]) == (661.9587, 264.1291)


def test_files_without_roi_are_read_as_before(tmp_path):
    path = tmp_path / "calib.txt"
    path.write_text("\n".join(line for line in CALIB.splitlines() if "roi" not in line) + "\n")
    assert read_calib(path)["cx"] == 661.9587
