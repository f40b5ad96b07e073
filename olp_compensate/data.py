"""Where the shipped data folders (``robots/``, ``grammars/``) are.

In a wheel they are the packages ``olp_compensate.robots`` and ``olp_compensate.grammars``
(mapped from the repository root by pyproject.toml). An editable install of the source tree
does not apply that mapping, so the folders are then read beside the package.
"""

from __future__ import annotations

from importlib import import_module
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from importlib.abc import Traversable


def data_folder(name: str) -> Path | Traversable:
    """The shipped folder ``name`` ('robots' or 'grammars').

    The folder of the package ``olp_compensate.NAME`` as a :class:`~pathlib.Path` when it is
    one folder on disk (a wheel, an editable install): what ``importlib.resources.files``
    gives, without importing importlib.resources (and through it tempfile and random, 2-4
    ms of a command's start); its Traversable otherwise (a zipped install)."""
    try:
        package = import_module(f"olp_compensate.{name}")
    except ModuleNotFoundError:
        source_tree = Path(__file__).resolve().parent.parent / name
        if source_tree.is_dir():
            return source_tree
        raise
    folders = [Path(p) for p in getattr(package, "__path__", ())]
    if len(folders) == 1 and folders[0].is_dir():
        return folders[0]
    from importlib import resources

    return resources.files(package)
