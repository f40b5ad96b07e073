"""The ``.pgx`` programs of a VAL3 project: read from the data file's folder."""

from __future__ import annotations

from pathlib import Path

from ...compensation.files import read_text


def project_programs(files) -> dict[str, str]:
    """The ``.pgx`` programs beside a VAL3 data file (its project's folder), by the names
    the report gives them (beside the data file's name)."""
    out = {}
    for path, name in zip(files.paths, files.names):
        for pgx in sorted(Path(path).parent.iterdir()):
            if pgx.suffix.lower() == ".pgx" and pgx.is_file():
                out[str(Path(name).parent / pgx.name) if Path(name).parent != Path(".")
                    else pgx.name] = read_text(pgx)
    return out
