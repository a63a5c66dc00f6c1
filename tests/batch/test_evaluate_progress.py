"""Progress without a terminal: one line per finished pair."""

from types import SimpleNamespace

from d3cli.batch.scoring import progress_bar, progress_done


def test_one_line_per_pair_without_terminal(capsys):
    pairs = [SimpleNamespace(name="p1"), SimpleNamespace(name="p2")]
    bar = progress_bar(pairs, True, "sgbm")  # pytest's stderr is not a terminal
    for pair, epe in zip(bar, (0.25, None)):
        progress_done(bar, {"pair": pair.name, "status": "ok", "time_s": 1.5, "epe": epe})
    lines = capsys.readouterr().err.splitlines()
    assert lines == ["[1/2]  p1  ok  1.50 s  EPE 0.250 px", "[2/2]  p2  ok  1.50 s"]


def test_quiet_prints_nothing(capsys):
    bar = progress_bar([SimpleNamespace(name="p1")], False, "sgbm")
    for pair in bar:
        progress_done(bar, {"pair": pair.name, "status": "ok"})
    assert capsys.readouterr().err == ""
