"""Bad input gives one clean ParseError with file, line, column and a caret; never a lark
traceback (regression guard: truncations and corruptions of the samples)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from olp_compensate.errors import OlpError, ParseError
from olp_compensate.programs import load, loads

ROOT = Path(__file__).resolve().parents[1]


def _error(text, dialect="rapid") -> ParseError:
    with pytest.raises(ParseError) as info:
        loads(text, dialect, "prog")
    return info.value


def test_binary_file_is_rejected_cleanly(tmp_path: Path):
    path = tmp_path / "robot.mod"
    path.write_bytes(b"MODULE A\r\n\x00\x01\x02\xff\x00ENDMODULE\r\n")
    with pytest.raises(ParseError) as info:
        load(path)
    assert info.value.line == 2 and info.value.column == 1
    assert "binary" in info.value.message


@pytest.mark.parametrize("text, line, column, words", [
    ("MODULE A\n  PROC main()\n    MoveL p1 v100, fine, tool0;\n  ENDPROC\nENDMODULE\n",
     3, 14, "v100"),
    ("MODULE A\n  PROC main()\n    MoveL Offs(p1,1,2, v100, fine, tool0;\n  ENDPROC\n"
     "ENDMODULE\n", 3, 41, "')'"),
    ("MODULE A\n  PROC main()\n    MoveL [[1,2,3],[1,0,0,0],[0,0,0,0]], v100, fine, tool0;\n"
     "  ENDPROC\nENDMODULE\n", 3, 11, "expected 4 components"),
    ("MODULE A\n  CONST robtarget p:=[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9]];\nENDMODULE\n",
     2, 51, "expected 6 values"),
    ("MODULE A\n  VAR num x := 3 +;\nENDMODULE\n", 2, 19, "';'"),
    ("MODULE A\n  PROC main()\n    IF a THEN\n      Stop;\n  ENDPROC\nENDMODULE\n", 5, 3,
     "ENDPROC"),
    ("MODULE A\n  PROC main()\n    TPWrite \"unterminated;\n  ENDPROC\nENDMODULE\n", 3, 13,
     "string"),
    ("MODULE A\n  PROC main(\n  ENDPROC\nENDMODULE\n", 2, 12, ""),
    ("PROC main()\nENDPROC\n", 1, 1, "PROC"),
    ("", 1, 1, "end of file"),
    ("MODULE A\r\n  CONST robtarget p:=[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]\r\n"
     "ENDMODULE\r\n", 2, 22, "unterminated"),
])
def test_error_position(text, line, column, words):
    err = _error(text)
    assert (err.line, err.column) == (line, column), str(err)
    assert words in err.message
    src, caret = err.context.split("\n")
    assert caret.index("^") == column - 1
    assert "\r" not in src


def test_vplus_errors():
    err = _error(".LOCATIONS\npick 1 2 3 4 5 6\n#pp 1 2 x\n.END\n", "vplus")
    assert (err.line, err.column) == (3, 9)
    err = _error(".PROGRAM a()\n  MOVE\n.END\n", "vplus")
    assert err.line == 2


def _corruptions(data: bytes, rng):
    n = len(data)
    for k in np.linspace(0, n, 80, dtype=int):
        yield data[:k]  # truncated
    for _ in range(80):
        k = int(rng.integers(0, n))
        yield data[:k] + bytes([int(rng.integers(0, 256))]) + data[k + 1:]  # one byte changed
        j = int(rng.integers(0, n))
        yield data[:k] + data[j:]  # a piece cut out


@pytest.mark.parametrize("name", ["cell_a.mod", "cell_b.pg"])
def test_corrupted_samples_never_leak_lark_errors(name: str):
    path = ROOT / "samples" / name
    dialect = "rapid" if name.endswith(".mod") else "vplus"
    rng = np.random.default_rng(0)
    for data in _corruptions(path.read_bytes(), rng):
        try:
            loads(data, dialect, name)
        except ParseError as err:
            assert err.line is not None and err.column is not None, str(err)
            assert err.context is not None
        except OlpError:
            pass


def test_binary_or_encrypted_module_is_one_line_without_its_bytes(tmp_path):
    """An encrypted module (control bytes, no NUL) and a binary file (NUL) are refused in
    one line that says so and echoes none of their bytes."""
    rng = np.random.default_rng(3)
    noise = bytes(rng.integers(0, 256, 4000, dtype="uint8").tolist())
    encrypted = noise.replace(b"\x00", b"\x01")
    for name, data in (("enc.mod", b"%%%\r\n  VERSION:1\r\n%%%\r\n" + encrypted),
                       ("bin.mod", b"MODULE A\n\x00\x01\x02ENDMODULE\n")):
        path = tmp_path / name
        path.write_bytes(data)
        with pytest.raises(ParseError) as info:
            load(path)
        err = info.value
        assert "binary or encrypted" in err.message
        assert err.context is None and "\n" not in str(err)
        assert all(32 <= ord(c) < 127 for c in str(err))
