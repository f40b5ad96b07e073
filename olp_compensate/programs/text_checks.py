"""Checks every program reader makes on bytes its format cannot hold: binary data, text in
UTF-16, malformed or non-finite numbers. One place for every dialect (RAPID, V+/AS, KRL,
FANUC TP, VAL3, URScript), so each refuses the same damage with the same one-line error,
file, line and column, never echoing the bytes.

Texts are decoded as latin-1 (one character per byte), so offsets are byte offsets.
"""

from __future__ import annotations

import bisect
import re

from ..errors import ParseError
from .pose_dialects import line_starts_of

_CONTROL = re.compile(r"[\x00-\x08\x0e-\x1a\x1c-\x1f\x7f]")
BINARY_SHARE = 0.01
"""A text whose first 64 KiB hold more than this share of control bytes is binary."""
_UTF16_BOMS = ("\xff\xfe", "\xfe\xff")
_NON_FINITE = re.compile(r"(?<![\w.])[-+]?(?:nan|inf(?:inity)?)\b", re.I)
_NUMBER_TAIL = re.compile(r"[A-Za-z0-9_.]")


def position(text: str, offset: int) -> tuple[int, int]:
    """1-based (line, column) of ``offset`` (lines end at LF, CR LF or CR)."""
    starts = line_starts_of(text[:offset + 1])
    k = bisect.bisect_right(starts, offset) - 1
    return k + 1, offset - starts[k] + 1


def _utf16(text: str) -> int | None:
    """Offset of the evidence that ``text`` is UTF-16 (its byte order mark, or NUL bytes at
    every other place of its first characters), or None."""
    if text.startswith(_UTF16_BOMS):
        return 0
    head = text[:512]
    if len(head) >= 4:
        for parity in (0, 1):
            others = head[1 - parity::2]
            if others and others.count("\x00") >= 0.9 * len(others) and \
                    head[parity::2].count("\x00") <= 0.1 * len(head[parity::2]):
                return 1 - parity
    return None


def check_text(text: str, file: str, hint: str = "") -> None:
    """Refuse a text that is UTF-16 or binary (a NUL byte, or many control bytes: an
    encrypted module, an image, a controller's binary ``.tp``...) before a reader sees it,
    in one line that does not echo its bytes. ``hint``: what to do instead of a binary
    file, appended."""
    at = _utf16(text)
    if at is not None:
        raise ParseError("the file is UTF-16 text (its bytes alternate with NULs): save it "
                         "as ASCII, Latin-1 or UTF-8", file, *position(text, at))
    head = text[:1 << 16]
    controls = len(_CONTROL.findall(head))
    nul = text.find("\x00")
    if nul < 0 and controls <= BINARY_SHARE * len(head):
        return
    first = nul if nul >= 0 else _CONTROL.search(head).start()
    raise ParseError(f"binary or encrypted file ({controls} control bytes in the first "
                     f"{len(head)}; first at this position): not a program in plain text"
                     + (f" ({hint})" if hint else ""), file, *position(text, first))


def check_number_end(text: str, end: int, file: str) -> None:
    """Refuse a number whose characters go on past what was read as the number
    (``2E+``, ``1.5.3``, ``12abc``): a malformed number, at its first character."""
    if end < len(text) and _NUMBER_TAIL.match(text, end):
        start = end
        while start > 0 and text[start - 1] in "0123456789.+-eE":
            start -= 1
        stop = end
        while stop < len(text) and (text[stop].isalnum() or text[stop] in "._+-"):
            stop += 1
        raise ParseError(f"malformed number {text[start:stop]!r}", file,
                         *position(text, start))


def check_not_non_finite(text: str, lo: int, hi: int, file: str, what: str = "") -> None:
    """Refuse ``nan``/``inf``/``infinity`` written as a value in ``text[lo:hi]``."""
    m = _NON_FINITE.search(text, lo, hi)
    if m is not None:
        raise ParseError(f"{(what + ' = ') if what else ''}{m.group()} is not a finite number",
                         file, *position(text, m.start()))


def check_xml(text: str, file: str, what: str = "XML") -> None:
    """Refuse a text that is not one well-formed XML document (cut short inside an element,
    several top-level elements, stray bytes), at the place the XML parser stops. Bytes are
    read as Latin-1 whatever the declaration says (the readers keep every byte); a text with
characters Latin-1 cannot hold (sent to the service as JSON) as UTF-8."""
    from xml.parsers import expat

    try:
        data, encoding = text.encode("latin-1"), "iso-8859-1"
    except UnicodeEncodeError:   # a service request's text: characters no file byte holds
        data, encoding = text.encode("utf-8"), "utf-8"
    parser = expat.ParserCreate(encoding=encoding)
    try:
        parser.Parse(data, True)
    except expat.ExpatError as exc:
        reason = expat.ErrorString(exc.code)
        hint = {"junk after document element": "several top-level elements: a fragment, not "
                                               "a whole file",
                "no element found": "the file ends before its elements close: cut short",
                "unclosed token": "the file ends inside an element: cut short"}.get(reason, "")
        raise ParseError(f"not well-formed {what}: {reason}" + (f" ({hint})" if hint else ""),
                         file, exc.lineno, exc.offset + 1) from None


def check_closed(text: str, clean: str, file: str, blocks) -> None:
    """Refuse a text cut short: a block opener of ``blocks`` ((opener, closer) keywords
    at line starts, ``GLOBAL`` allowed before the opener, any case) without its closer.
    ``clean``: the text with its comments blanked (offsets kept)."""
    for opener, closer in blocks:
        opened = re.findall(rf"^[ \t]*(?:GLOBAL[ \t]+)?{opener}\b", clean, re.I | re.M)
        closed = re.findall(rf"^[ \t]*{closer}\b", clean, re.I | re.M)
        if len(opened) > len(closed):
            raise ParseError(f"{opener} without {closer}: the file is cut short", file,
                             *position(text, len(text.rstrip())))
