"""How a parse runs: the analysed grammar is cached on disk (user cache folder), and a
missing, stale, corrupt or unwritable cache only costs the time to build the parser again;
the garbage collector's full collections are held off while a parse runs, and only then."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from olp_compensate.programs import grammar, loads
from olp_compensate.programs.rapid import reader as rapid

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = (ROOT / "samples" / "cell_a.mod").read_bytes().decode("latin-1")


def _fresh_parser():
    """A parser built now (not the process-wide one of ``grammar.parser``)."""
    return grammar.parser.__wrapped__("rapid.lark", rapid.Callbacks, ("start", "call"))


def _parse_with(parser, text: str):
    real = rapid.parser
    rapid.parser = lambda *args: parser
    try:
        return loads(text, "rapid", "cell_a.mod")
    finally:
        rapid.parser = real


@pytest.fixture()
def cache_home(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setenv("LOCALAPPDATA", str(tmp_path / "cache"))
    return tmp_path / "cache" / "olp-compensate"


def test_the_parser_is_cached_and_parses_the_same(cache_home):
    expected = loads(SAMPLE, "rapid", "cell_a.mod")
    built = _fresh_parser()
    (cache,) = cache_home.iterdir()
    assert cache.name.startswith("rapid-start-call-") and cache.stat().st_size > 0
    loaded = _fresh_parser()  # from the file
    assert _parse_with(built, SAMPLE) == expected
    assert _parse_with(loaded, SAMPLE) == expected


def test_a_corrupt_cache_is_rebuilt(cache_home):
    _fresh_parser()
    (cache,) = cache_home.iterdir()
    cache.write_bytes(cache.read_bytes()[:200])  # truncated while another run wrote it
    assert _parse_with(_fresh_parser(), SAMPLE) == loads(SAMPLE, "rapid", "cell_a.mod")


@pytest.mark.skipif(os.name == "nt", reason="POSIX permissions")
def test_no_usable_cache_folder_means_no_cache(tmp_path, monkeypatch):
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("")
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocker))  # makedirs fails under a file
    assert grammar.cache_file("rapid-start") is None
    assert _parse_with(_fresh_parser(), SAMPLE) == loads(SAMPLE, "rapid", "cell_a.mod")
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/path")
    monkeypatch.setenv("HOME", "relative")
    assert grammar.cache_file("rapid-start") is None


def test_an_unwritable_cache_file_is_not_an_error(cache_home):
    """A cache path lark can neither read nor write (a folder in its place: this fails
    for root too) only means building the parser."""
    path = Path(grammar.cache_file("rapid-start-call"))
    path.mkdir(parents=True)
    assert _parse_with(_fresh_parser(), SAMPLE) == loads(SAMPLE, "rapid", "cell_a.mod")
    assert path.is_dir() and not any(path.iterdir())


def test_the_library_leaves_the_garbage_collector_alone(monkeypatch):
    """Only the command line touches the collector: parsing, resolving and compensating
    a program never switch it off nor change its thresholds."""
    import gc

    from olp_compensate.calibration.calibration import nominal_calibration
    from olp_compensate.programs.object_model.task import compensate_program
    from olp_compensate.errors import ParseError
    from olp_compensate.kinematics.robot import load_robot

    cal = nominal_calibration(load_robot("abb_irb2400"))
    touched = []
    monkeypatch.setattr(gc, "disable", lambda: touched.append("disable"))
    monkeypatch.setattr(gc, "set_threshold", lambda *a: touched.append(("threshold", a)))
    compensate_program(SAMPLE, "rapid", cal)
    with pytest.raises(ParseError):
        loads("MODULE A\n  PROC main(\nENDMODULE\n", "rapid")
    assert touched == []
