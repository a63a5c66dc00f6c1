"""Comments, docstrings, configs, scripts and docs say what and why, never when.

docs/design.md: the code's comments and docstrings, the bundled YAML configs and the
scripts describe the code as it is.  They name no work session or issue number, carry
no dates of measurements and no "before / until now" narrative; a measured reason for a
choice is stated as a fact of the alternatives (and the command that measures it).  The
history lives in git and CHANGELOG.md.

One test per tree, so that a tree can be checked alone (``-k "not docs"``: the code, the
configs and the scripts only).  A failure lists every offending ``file:line``.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

#: Everywhere: a work session or an issue by number ("session 19", "Issue 16").
SESSION_OR_ISSUE = (
    re.compile(r"\bsession [0-9]", re.IGNORECASE),
    re.compile(r"\bissue [0-9]", re.IGNORECASE),
)
#: In the code, the configs and the scripts too: a date (of a measurement, a change) and
#: the history phrases these trees once used.  A date written as a code literal
#: (````2001-12-14````, the YAML 1.1 example of d3cli/config/yamlfile.py) is data.
CODE_ONLY = (
    re.compile(r"\b20[0-9][0-9]-[01][0-9]-[0-3][0-9]\b"),
    re.compile(r"\buntil now\b", re.IGNORECASE),
    re.compile(r"\bused to end\b", re.IGNORECASE),
    re.compile(r"\bthe driver before\b", re.IGNORECASE),
    re.compile(r"\b(?:a|per) map before\b", re.IGNORECASE),
    re.compile(r"\bbefore families existed\b", re.IGNORECASE),
    re.compile(r"\bwas once\b", re.IGNORECASE),
)
_CODE_LITERAL = re.compile(r"``[^`]*``")


def _text_files(folder: Path, suffixes: tuple[str, ...] | None) -> list[Path]:
    """Files under ``folder`` (``suffixes`` None: every file that reads as UTF-8 text)."""
    found = []
    for path in sorted(folder.rglob("*")):
        if not path.is_file() or "__pycache__" in path.parts:
            continue
        if suffixes is not None and path.suffix not in suffixes:
            continue
        found.append(path)
    return found


def _trees() -> dict[str, tuple[list[Path], tuple[re.Pattern, ...]]]:
    code = SESSION_OR_ISSUE + CODE_ONLY
    return {
        "code-d3cli": (_text_files(ROOT / "d3cli", (".py",)), code),
        "code-configs": (_text_files(ROOT / "configs", (".yaml", ".yml")), code),
        "code-scripts": (_text_files(ROOT / "scripts", None), code),
        "docs-README": ([ROOT / "README.md"], SESSION_OR_ISSUE),
        "docs-CHANGELOG": ([ROOT / "CHANGELOG.md"], SESSION_OR_ISSUE),
        "docs-pages": (_text_files(ROOT / "docs", (".md",)), SESSION_OR_ISSUE),
    }


def offences(text: str, patterns) -> list[tuple[int, str]]:
    """``(line number, line)`` of every line of ``text`` that one of ``patterns`` matches
    (outside ````code literals```` for the date pattern)."""
    found = []
    for number, line in enumerate(text.splitlines(), start=1):
        bare = _CODE_LITERAL.sub("", line)
        if any(p.search(bare if p is CODE_ONLY[0] else line) for p in patterns):
            found.append((number, line.strip()))
    return found


@pytest.mark.parametrize("tree", sorted(_trees()))
def test_no_history_in(tree):
    files, patterns = _trees()[tree]
    assert files, f"{tree}: no files found"
    bad = []
    for path in files:
        try:
            text = path.read_text(encoding="utf-8")
        except (UnicodeDecodeError, FileNotFoundError):
            continue  # a binary file under scripts/, or a file being replaced right now
        bad += [f"{path.relative_to(ROOT)}:{n}: {line[:160]}" for n, line in offences(text, patterns)]
    assert not bad, (f"{len(bad)} line(s) say when instead of what and why (no session or issue "
                     "numbers, dates or 'until now'; docs/design.md):\n" + "\n".join(bad))


@pytest.mark.parametrize("line", [
    "# 2026-11-28 (session 16): on the 22 Middlebury pairs",
    "Passes at the second level only (Session 20): the same maps",
    "# Issue 16 (driving scenes)",
    "help='default 5, issue 10's baseline'",
    "every_level: false  # coarsest level only (since 2026-11-28)",
    "Until now SIGTERM was ignored once the command's status was decided",
    "candidate parts: 7.9 s a map before, whole-image masks",
])
def test_the_patterns_catch(line):
    assert offences(line, SESSION_OR_ISSUE + CODE_ONLY) == [(1, line.strip())]


@pytest.mark.parametrize("line", [
    "the sweep runs before the fill",
    "session = _session(cfg.model)  # onnxruntime sessions by model",
    "``yes``/``on`` are true, ``2001-12-14`` a date (YAML 1.1)",
    "the same md5 before and after a bit-identical speed-up",
    "a thread that was descheduled on a shared host",
    "give an empty or new folder, or the same --seed/--width/--height as before",
])
def test_the_patterns_spare(line):
    assert offences(line, SESSION_OR_ISSUE + CODE_ONLY) == []
