"""The JSON schemas of the project's files (package data ``olp_compensate.schemas``) and
the check of a document against one. A schema itself is checked against its metaschema by
the tests, not at every read (that took 80 ms of each olp-fix run)."""

from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

_FOLDER = Path(__file__).resolve().parent.parent / "schemas"
"""The package's ``schemas`` folder (read as files: importlib.resources would import
zipfile for it, 3 ms of every run)."""


@lru_cache(maxsize=None)
def schema_bytes(name: str) -> bytes:
    """The bytes of schema ``name`` (``"calibration-v1.json"``)."""
    return (_FOLDER / name).read_bytes()


@lru_cache(maxsize=None)
def schema(name: str) -> dict:
    """Schema ``name`` as a dictionary."""
    return json.loads(schema_bytes(name))


@lru_cache(maxsize=None)
def validator(name: str):
    """A jsonschema validator of documents of schema ``name`` (jsonschema imported here:
    it takes 45-70 ms)."""
    import jsonschema

    found = schema(name)
    return jsonschema.validators.validator_for(found)(found)


def schema_error(doc, check) -> tuple[str, str] | None:
    """(JSON path, message) of the error jsonschema finds most relevant in ``doc`` under
    the validator ``check``, or None for a valid document."""
    import jsonschema

    exc = jsonschema.exceptions.best_match(check.iter_errors(doc))
    if exc is None:
        return None
    return "/".join(str(p) for p in exc.absolute_path) or "(top level)", exc.message
