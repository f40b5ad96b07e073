"""Numbers written again as they were read: a document read, converted to SI and written
back must come back byte for byte (mm -> m -> mm, degrees -> radians -> degrees, a
quaternion through a matrix each move the last digit otherwise).

:func:`keep_numbers` walks the document to write beside two others at the same JSON paths:
``again``, what the object as read writes (the conversions' round trip), and ``read``, the
document as read. Where the new number equals ``again``'s, the value did not change since
the read, and ``read``'s number is written; every other number (changed, or at a path the
read document lacks) is written anew.
"""

from __future__ import annotations


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _at(container, key):
    """``container[key]`` for a dict key or a list index, else None."""
    if isinstance(container, dict):
        return container.get(key)
    if isinstance(container, list) and isinstance(key, int) and key < len(container):
        return container[key]
    return None


def keep_numbers(new, again, read):
    """``new`` (a JSON value) with each number that equals ``again``'s at its path replaced
    by ``read``'s number there (see the module docstring); ``new`` is not modified."""
    if isinstance(new, dict):
        return {key: keep_numbers(value, _at(again, key), _at(read, key))
                for key, value in new.items()}
    if isinstance(new, list):
        return [keep_numbers(value, _at(again, k), _at(read, k)) for k, value in enumerate(new)]
    if _is_number(new) and _is_number(again) and _is_number(read) and new == again:
        return read
    return new
