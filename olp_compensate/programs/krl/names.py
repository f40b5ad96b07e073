"""KRL module names: KSS loads a module only when the ``DEF`` of its ``.src`` and the
``DEFDAT`` of its ``.dat`` carry the file's name, so outputs written under new names are
renamed inside."""

from __future__ import annotations

import re
from pathlib import Path


KRL_NAME_LIMIT = 24
"""Characters of a KRL name (KSS refuses longer module names)."""


def match_krl_names(paths, outputs, data: list[bytes]) -> tuple[list[bytes], list[str]]:
    """KRL files' new bytes with the main ``DEF`` (``.src``) and the ``DEFDAT`` (``.dat``)
    renamed after the output file when its name differs from the input's (KSS loads a
    module only when the names inside match the file names); every other byte kept.
    Returns ``(data, notes)``: one note per file renamed, and per name KSS would refuse."""
    new, notes = [], []
    for path, out, text in zip(paths, outputs, data):
        old_name, new_name = Path(path).stem, Path(out).stem
        if old_name.lower() == new_name.lower():
            new.append(text)
            continue
        word = "DEFDAT" if Path(path).suffix.lower() == ".dat" else "DEF"
        try:
            old_bytes, new_bytes = old_name.encode("latin-1"), new_name.encode("latin-1")
        except UnicodeEncodeError:       # a file name no KRL text can hold: nothing renamed
            new.append(text)
            notes.append(f"{out}: {word} kept: {new_name!r} is no KRL name KSS accepts (a "
                         f"letter or _ first, at most {KRL_NAME_LIMIT} letters, digits or "
                         f"_): choose another output name with -o")
            continue
        pattern = (rb"^([ \t]*DEFDAT[ \t]+)(%s)(?![\w$])" if word == "DEFDAT" else
                   rb"^([ \t]*(?:GLOBAL[ \t]+)?DEF(?:FCT[ \t]+[\w$]+(?:\[[^\]\r\n]*\])?)?"
                   rb"[ \t]+)(%s)(?=[ \t]*\()")
        found = re.compile(pattern % re.escape(old_bytes),
                           re.IGNORECASE | re.MULTILINE).search(text)
        if found is None:
            new.append(text)
            continue
        new.append(text[:found.start(2)] + new_bytes + text[found.end(2):])
        notes.append(f"{out}: {word} {found.group(2).decode('latin-1')} renamed {new_name} "
                     f"to match the file name (KSS loads a module only so); programs that "
                     f"call it by the old name need the new one")
        if not re.fullmatch(r"[A-Za-z_$][\w$]{0,%d}" % (KRL_NAME_LIMIT - 1), new_name,
                            re.ASCII):
            notes.append(f"{out}: {new_name!r} is no KRL name KSS accepts (a letter or _ "
                         f"first, at most {KRL_NAME_LIMIT} letters, digits or _): choose a "
                         f"shorter output name with -o")
    return new, notes
