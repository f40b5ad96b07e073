"""One exception family for everything a user can get wrong.

The command-line front ends turn each of these into one line on stderr and a non-zero
exit code; library callers catch :class:`OlpError`.
"""

from __future__ import annotations


class OlpError(Exception):
    """Base class of every error caused by bad input, not by a bug."""


class DataError(OlpError):
    """Measurements or other tabular input that cannot be used (missing column, NaN...)."""


class ModelError(OlpError):
    """A robot description or calibration that cannot be used (unknown robot, wrong
    fingerprint or version, not a serial chain...)."""


class UnreachableTarget(OlpError):
    """A pose the robot cannot reach (raised only where a single pose was asked for;
    batched solvers return the failure as a value)."""


class ParseError(OlpError):
    """A program or data file that does not parse.

    Parameters
    ----------
    message : what was expected and what arrived.
    file : path as the user gave it (or ``"<string>"``).
    line, column : 1-based position of the offending character.
    context : the offending source line with a caret under the spot (optional).
    """

    def __init__(self, message: str, file: str = "<string>", line: int | None = None,
                 column: int | None = None, context: str | None = None):
        self.message = message
        self.file = file
        self.line = line
        self.column = column
        self.context = context
        super().__init__(str(self))

    def __str__(self) -> str:
        where = self.file
        if self.line is not None:
            where += f":{self.line}"
            if self.column is not None:
                where += f":{self.column}"
        return f"{where}: {self.message}"
