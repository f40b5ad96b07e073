"""The robot languages olp-fix reads, each one :class:`Language` registered by name.

A built-in language is a folder ``programs/<name>/`` whose ``language`` module defines
``LANGUAGE`` (listed in :data:`BUILT_IN`); another one (a plug-in, a test's toy dialect) is
added with :func:`register`. The pipeline (``compensation/files.py``, ``cli/fix*.py``) asks
this registry for a file's language and calls its hooks; it names no language itself.

The ``language`` modules are light (standard library only at import): ``olp-fix --help``
lists every extension without loading a parser.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from ..errors import DataError, ParseError

BUILT_IN = ("rapid", "vplus", "krl", "fanuc", "val3", "urscript")
"""The folders of ``programs/`` holding a built-in language, in the order help lists them."""


@dataclass(frozen=True)
class Language:
    """One robot language as the pipeline sees it.

    name : what ``--dialect`` and the report call it (``"krl"``).
    title : the language as users know it (``"KUKA KRL"``), for help and messages.
    extensions : file name endings, lower case with the dot (``(".src", ".dat")``).
    compensate : ``(files, texts, run) -> FilesResult``: the files of one unit
        (:class:`~olp_compensate.compensation.files.ProgramFiles`), their decoded texts and
        the run's :class:`~olp_compensate.compensation.files.CompensationRun`; reads,
        solves and writes (see ``compensation/files.py`` for the helpers it may use).
    unit_key : ``(path, given_alone) -> key``: files of one key form one unit (a RAPID
        task's modules; a KRL ``.src`` and ``.dat``); None: each file alone.
    member_order : sort key of a unit's files, ``(path, name) -> key`` (the order
        ``compensate`` receives them in); None: by path.
    partner : ``path -> path | None``: a file that comes with one given alone (KRL's ``.dat``).
    check_complete : ``(names, data: list[bytes]) -> None``: raises
        :class:`~olp_compensate.errors.DataError` for a program without any target that
        looks cut short (beyond every file blank, which is always refused).
    loadable_outputs : ``(paths, outputs, data) -> (data, notes)``: the outputs' bytes as
        the controller loads them under their new names (KRL renames ``DEF``/``DEFDAT``).
    stated_loads : ``(texts: dict[name, str], config_paths) -> ProgramLoads``: the loads
        the program states (:mod:`olp_compensate.programs.payloads`); None: none.
    controller_warning : ``controller -> str | None``: a warning for a run without the
        controller's own model where the controller is known to run one (UR).
    warm_up : loads the parser in the parent of a process pool (a grammar loads once).
    emits_joints : whether ``--emit joints`` can write the language's targets as joints.
    """

    name: str
    title: str
    extensions: tuple[str, ...]
    compensate: Callable[..., Any]
    unit_key: Callable[[Path, bool], Any] | None = None
    member_order: Callable[[Path, str], Any] | None = None
    partner: Callable[[Path], Path | None] | None = None
    check_complete: Callable[[list, list], None] | None = None
    loadable_outputs: Callable[[list, list, list], tuple[list, list]] | None = None
    stated_loads: Callable[[dict, Any], Any] | None = None
    controller_warning: Callable[[Any], str | None] | None = None
    warm_up: Callable[[], None] | None = None
    emits_joints: bool = False


_REGISTERED: dict[str, Language] = {}


def lazy(module: str, name: str, package: str | None = None) -> Callable[..., Any]:
    """A hook that imports ``name`` from ``module`` (relative to ``package``) when first
    called, so a ``language`` module stays light to import."""
    def hook(*args, **kwargs):
        return getattr(importlib.import_module(module, package), name)(*args, **kwargs)
    hook.__name__ = hook.__qualname__ = name
    return hook


def register(language: Language) -> Language:
    """Add ``language`` (or replace the one of its name); its extensions must be new."""
    if not language.extensions or any(not e.startswith(".") or e != e.lower()
                                      for e in language.extensions):
        raise DataError(f"language {language.name!r}: extensions must be lower case and "
                        f"start with a dot, got {language.extensions!r}")
    _load_built_in()
    taken = {e: lang.name for lang in _REGISTERED.values() if lang.name != language.name
             for e in lang.extensions}
    clash = [e for e in language.extensions if e in taken]
    if clash:
        raise DataError(f"language {language.name!r}: extension {clash[0]} is already "
                        f"{taken[clash[0]]!r}'s")
    _REGISTERED[language.name] = language
    return language


def unregister(name: str) -> None:
    """Remove a language added with :func:`register` (a test's toy); built-ins stay."""
    if name in BUILT_IN:
        raise DataError(f"{name!r} is a built-in language")
    _REGISTERED.pop(name, None)


def _load_built_in() -> None:
    for name in BUILT_IN:
        if name not in _REGISTERED:
            module = importlib.import_module(f"{__package__}.{name}.language")
            _REGISTERED[name] = module.LANGUAGE


def languages() -> tuple[Language, ...]:
    """Every language: the built-ins in :data:`BUILT_IN` order, then those registered."""
    _load_built_in()
    return tuple(_REGISTERED.values())


def names() -> tuple[str, ...]:
    """Every language's name (the choices of ``--dialect``)."""
    return tuple(lang.name for lang in languages())


def extensions() -> dict[str, str]:
    """File extension (lower case, with the dot) -> language name."""
    return {e: lang.name for lang in languages() for e in lang.extensions}


def language_named(name: str) -> Language:
    """The language called ``name``; :class:`DataError` naming the known ones."""
    _load_built_in()
    try:
        return _REGISTERED[name]
    except KeyError:
        raise DataError(f"unknown dialect {name!r}; expected one of "
                        f"{', '.join(names())}") from None


def language_of(path: str | Path) -> Language:
    """The language of a file from its extension (any case)."""
    ext = Path(path).suffix.lower()
    found = extensions().get(ext)
    if found is None:
        raise ParseError(f"unknown program extension {ext or '(none)'!r}; expected one of "
                         f"{', '.join(sorted(extensions()))} or an explicit dialect", str(path))
    return _REGISTERED[found]
