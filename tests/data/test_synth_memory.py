"""`d3stereo synth` at a size the memory cannot hold: one ``Error:`` line before any work
(at 8192x8192 under a 6 GB address-space limit it ran for minutes and died inside
OpenBLAS's allocator), and a MemoryError while rendering is one ``Error:`` line too."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest
from click.testing import CliRunner

from d3cli.cli import main
from d3cli.data.synth import dataset
from d3cli.errors import InputError


def test_a_size_beyond_the_memory_left_is_refused_before_any_work(tmp_path, monkeypatch):
    monkeypatch.setattr(dataset, "memory_left", lambda: (5_000_000_000, "this process may still use under its "
                                                                        "limit of 6.0 GB (ulimit -v)"))
    result = CliRunner().invoke(main, ["synth", str(tmp_path / "s"), "--n", "1", "--width", "8192", "--height", "8192"])
    assert result.exit_code == 1
    assert result.output == ("Error: synth: rendering a 8192x8192 pair needs about 13.4 GB of memory, more than this "
                             "process may still use under its limit of 6.0 GB (ulimit -v): 5.0 GB; use a smaller "
                             "--width/--height (about --width 4992 --height 4992 fits)\n")
    assert not (tmp_path / "s").exists()  # nothing written


def test_no_memory_at_all_asks_to_free_some(monkeypatch):
    monkeypatch.setattr(dataset, "memory_left", lambda: (1000, "the system has free (RAM and swap)"))
    with pytest.raises(InputError) as info:
        dataset.render_pair(seed=0, width=64, height=64)
    assert str(info.value) == ("synth: rendering a 64x64 pair needs about 1 MB of memory, more than the system "
                               "has free (RAM and swap): 0 MB; free memory, or raise the limit")


def test_a_memory_error_while_rendering_is_one_error_line(tmp_path, monkeypatch):
    def exhausted(*args, **kwargs):
        raise MemoryError("Unable to allocate 3.0 GiB for an array")

    monkeypatch.setattr(dataset, "render_pair", exhausted)
    result = CliRunner().invoke(main, ["synth", str(tmp_path / "s"), "--n", "1", "--width", "64", "--height", "64"])
    assert result.exit_code == 1
    assert result.output == ("Error: synth: out of memory rendering a 64x64 pair (it needs about 1 MB); use a "
                             "smaller --width/--height, or free memory\n")


def test_a_memory_error_while_writing_is_one_error_line(tmp_path, monkeypatch):
    def exhausted(*args, **kwargs):
        raise MemoryError

    monkeypatch.setattr(dataset, "write_image", exhausted)
    result = CliRunner().invoke(main, ["synth", str(tmp_path / "s"), "--n", "1", "--width", "64", "--height", "64"])
    assert result.exit_code == 1
    assert result.output.startswith("Error: synth: out of memory rendering a 64x64 pair")


def test_the_largest_size_under_an_address_space_limit_is_refused_at_once(tmp_path):
    """The reproduction itself: 8192x8192 with ``ulimit -v`` 6 GB."""
    resource = pytest.importorskip("resource")
    limit = 6 * 1024**3

    def limited():
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    t0 = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "d3cli", "synth", str(tmp_path / "s"), "--n", "1",
                           "--width", "8192", "--height", "8192"], capture_output=True, text=True, timeout=300,
                          preexec_fn=limited)
    assert done.returncode == 1, done.stderr
    assert done.stderr.startswith("Error: synth: rendering a 8192x8192 pair needs about 13.4 GB of memory, more "
                                  "than this process may still use under its limit of 6.4 GB (ulimit -v): ")
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr
    assert time.monotonic() - t0 < 60  # was 178 s of rendering first
    assert not (tmp_path / "s").exists()


def test_render_pair_turns_a_memory_error_into_its_error(monkeypatch):
    def exhausted(*args, **kwargs):
        raise MemoryError

    monkeypatch.setattr(dataset, "pothole_truth", exhausted)  # the last allocation of a render
    with pytest.raises(InputError) as info:
        dataset.render_pair(seed=0, width=64, height=64)
    assert str(info.value) == ("synth: out of memory rendering a 64x64 pair (it needs about 1 MB); use a smaller "
                               "--width/--height, or free memory")
