"""What a person sees on stderr: warnings on lines of their own beside the progress bar,
``-v`` limited to d3stereo's lines, progress from long commands."""

from __future__ import annotations

import fcntl
import os
import pty
import select
import struct
import subprocess
import sys
import termios

from click.testing import CliRunner

from d3cli.cli import main
from tests.helpers import textured_pair, write_png


def _screen(raw: str) -> list[str]:
    """The lines a terminal shows for ``raw``: ``\\r`` returns to the line's start and
    what follows overwrites it; ``\\n`` starts a new line."""
    lines, line, col = [], [], 0
    for ch in raw:
        if ch == "\r":
            col = 0
        elif ch == "\n":
            lines.append("".join(line).rstrip())
            line, col = [], 0
        elif ch >= " ":
            if col < len(line):
                line[col] = ch
            else:
                line.append(ch)
            col += 1
    lines.append("".join(line).rstrip())
    return lines


def _on_a_terminal(args, timeout=120) -> tuple[int, str]:
    """``d3stereo ARGS`` with stderr on a pseudo-terminal: (exit status, what it wrote there)."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 200, 0, 0))  # 24 rows of 200 columns
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [os.getcwd(), os.environ.get("PYTHONPATH")]))}
    proc = subprocess.Popen([sys.executable, "-m", "d3cli", *args], stdout=subprocess.DEVNULL, stderr=slave, env=env)
    os.close(slave)
    chunks = []
    try:
        while True:
            ready, _, _ = select.select([master], [], [], timeout)
            if not ready:
                break
            try:
                data = os.read(master, 65536)
            except OSError:  # EIO: the child closed its end
                break
            if not data:
                break
            chunks.append(data)
    finally:
        os.close(master)
        status = proc.wait(timeout=timeout)
    return status, b"".join(chunks).decode("utf-8", "replace")


def test_a_warning_is_never_glued_to_the_progress_bar_on_a_terminal(tmp_path):
    root = tmp_path / "pairs"
    for i, name in enumerate(["a", "b", "c", "d"]):
        (root / name).mkdir(parents=True)
        left, right, _ = textured_pair(6, size=(96, 160), seed=i)
        if name in "bc":  # swapped: warned about
            left, right = right, left
        write_png(root / name / "left.png", left)
        write_png(root / name / "right.png", right)
    status, raw = _on_a_terminal(["run", str(root), "-o", str(tmp_path / "out"), "--method", "sgbm",
                                  "--max-disparity", "16"])
    assert status == 0, raw
    shown = _screen(raw)
    warned = [line for line in shown if "WARNING:" in line]
    assert len(warned) == 2, shown
    assert all(line.startswith("WARNING: ") and line.endswith("check the inputs before trusting this map")
               for line in warned), shown
    assert any("sgbm" in line and "4/4" in line for line in shown), shown  # the bar was drawn


def test_verbose_shows_d3stereos_lines_and_not_pillows(tmp_path, pairs_root):
    result = CliRunner().invoke(main, ["run", str(pairs_root), "-o", str(tmp_path / "out"), "--method", "sgbm", "-v"])
    assert result.exit_code == 0, result.output
    lines = result.stderr.splitlines()
    assert any(line.startswith("DEBUG: ") for line in lines), lines  # d3stereo's own debug lines
    assert not [line for line in lines if "STREAM b'" in line]


def test_double_verbose_shows_the_libraries_debug_lines(tmp_path, pairs_root):
    result = CliRunner().invoke(main, ["run", str(pairs_root), "-o", str(tmp_path / "out"), "--method", "sgbm", "-vv"])
    assert result.exit_code == 0, result.output
    assert [line for line in result.stderr.splitlines() if line.startswith("DEBUG: STREAM b'IHDR'")]


def test_synth_says_each_pair_as_it_is_written(tmp_path):
    result = CliRunner().invoke(main, ["synth", str(tmp_path / "s"), "--n", "2", "--width", "64", "--height", "48"])
    assert result.exit_code == 0, result.output
    lines = result.stderr.splitlines()
    assert [line.rsplit("  ", 1)[0] for line in lines] == ["[1/2]  synth-0000-sun-asphalt  written",
                                                          "[2/2]  synth-0001-dusk-cement  written"]
    assert all(line.endswith(" s") for line in lines)
    assert result.stdout == f"wrote 2 pairs to {tmp_path / 's'}\n"


def test_synth_quiet_says_nothing(tmp_path):
    result = CliRunner().invoke(main, ["synth", str(tmp_path / "s"), "--n", "1", "--width", "64", "--height", "48",
                                       "-q"])
    assert result.exit_code == 0, result.output
    assert (result.stdout, result.stderr) == ("", "")


def test_synth_draws_a_bar_on_a_terminal(tmp_path):
    status, raw = _on_a_terminal(["synth", str(tmp_path / "s"), "--n", "2", "--width", "64", "--height", "48"])
    assert status == 0, raw
    assert any(line.startswith("synth: 100%") and "2/2" in line for line in _screen(raw)), _screen(raw)
