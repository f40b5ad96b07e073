"""Where the shipped data folders (``robots/``, ``grammars/``) are.

In a wheel they are the packages ``olp_compensate.robots`` and ``olp_compensate.grammars``
(mapped from the repository root by pyproject.toml). An editable install of the source tree
does not apply that mapping, so the folders are then read beside the package.
"""

from __future__ import annotations

from importlib import resources
from importlib.abc import Traversable
from pathlib import Path


def data_folder(name: str) -> Traversable:
    """The shipped folder ``name`` ('robots' or 'grammars')."""
    try:
        return resources.files(f"olp_compensate.{name}")
    except ModuleNotFoundError:
        source_tree = Path(__file__).resolve().parent.parent / name
        if source_tree.is_dir():
            return source_tree
        raise
