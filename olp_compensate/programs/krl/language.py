"""KUKA KRL as the pipeline sees it: a ``.src`` with its ``.dat`` of the same stem, the
controller's ``$config.dat`` (``--config``) for tools, bases and loads."""

from __future__ import annotations

from pathlib import Path

from ..languages import Language, lazy

EXTENSIONS = (".src", ".dat")


def compensate(files, texts: list[str], run):
    """Read the pair with the ``$config.dat`` among the ``--config`` files (the FANUC
    ``.VA`` files there are not KRL's), solve and write both files."""
    from ...compensation.files import pose_program_result, read_text
    from .reader import parse_krl
    from .rules import KRL

    by_ext = {Path(n).suffix.lower(): (n, t) for n, t in zip(files.names, texts)}
    src, dat = by_ext.get(".src", (None, None)), by_ext.get(".dat", (None, None))
    configs = {path: read_text(Path(path)) for path in run.backup.paths
               if Path(path).suffix.lower() != ".va"}
    program = parse_krl(src[1], dat[1], src[0] or "<src>", dat[0] or "<dat>", configs)
    return pose_program_result(files, program, KRL, run)


def partner(path: Path) -> Path | None:
    """The ``.dat`` of a ``.src`` (or the reverse), same stem, any case, if it exists."""
    want = ".dat" if path.suffix.lower() == ".src" else ".src"
    for candidate in path.parent.glob(f"{path.stem}.*"):
        if candidate.suffix.lower() == want and candidate.stem == path.stem:
            return candidate
    return None


LANGUAGE = Language(
    name="krl", title="KUKA KRL", extensions=EXTENSIONS, compensate=compensate,
    unit_key=lambda path, given_alone: (path.parent, path.stem.lower()),
    member_order=lambda path, name: path.suffix.lower() != ".src",       # .src first
    partner=partner, loadable_outputs=lazy(".names", "match_krl_names", __package__),
    stated_loads=lazy(".payload", "stated_loads", __package__))
