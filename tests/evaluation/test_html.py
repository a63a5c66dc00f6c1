"""report.html: valid HTML, every pair named, no broken local link, sorted thumbnails."""

from html.parser import HTMLParser
from urllib.parse import unquote

import numpy as np

from d3cli.data import io
from d3cli.evaluation.html import histogram_svg, write_report_html


class Collector(HTMLParser):
    def __init__(self):
        super().__init__()
        self.links, self.stack, self.ids, self.text = [], [], set(), []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag not in ("br", "img", "meta", "rect", "input"):
            self.stack.append(tag)
        self.links += [attrs[k] for k in ("href", "src") if k in attrs]
        if "id" in attrs:
            self.ids.add(attrs["id"])

    def handle_endtag(self, tag):
        if tag in ("rect",):
            return
        assert self.stack and self.stack[-1] == tag, (tag, self.stack[-5:])
        self.stack.pop()

    def handle_data(self, data):
        self.text.append(data)


def test_report_is_valid_and_links_resolve(tmp_path):
    rows = [
        {"pair": "good", "family": "kitti", "status": "ok", "epe": 0.5, "d1_all": 1.0, "time_s": 1.0},
        {"pair": "bad", "family": "kitti", "status": "ok", "epe": 5.0, "d1_all": 30.0, "time_s": 1.0},
        {"pair": "road<1>", "family": "road", "status": "ok", "psnr": 20.0, "time_s": 2.0},
        {"pair": "broken", "family": "road", "status": "failed", "error": "Error: x & y"},
    ]
    for name in ("good", "bad"):
        (tmp_path / name).mkdir()
        io.write_image(tmp_path / name / "panel.png", np.zeros((4, 8, 3), np.uint8))
    path = write_report_html(tmp_path, rows, title="t", config={"a": 1}, versions={"numpy": "1"})
    text = path.read_text()
    parser = Collector()
    parser.feed(text)
    parser.close()
    assert parser.stack == []
    assert "http" not in " ".join(parser.links) and "<link" not in text  # no network
    for link in parser.links:
        if link.startswith("#"):
            assert link[1:] in parser.ids
        else:
            assert (tmp_path / unquote(link)).is_file(), link
    joined = "".join(parser.text)
    for row in rows:
        assert row["pair"] in joined
    assert text.index('id="bad"') < text.index('id="good"')  # worst first
    assert "<svg" in text


def test_histogram_counts():
    svg = histogram_svg([0.0, 0.1, 1.0], label="epe", bins=2)
    assert svg.count("<rect") == 2 and ": 2</title>" in svg and ": 1</title>" in svg
