"""A robot task of several RAPID modules: which module-level data each module keeps to
itself.

The controller loads every module of a task (``CalibData.mod``, user modules, system
modules such as ``user.sys``) into one name space (RAPID Reference Manual, "Data scope"):

- module-level data declared without ``LOCAL`` (``CONST``/``VAR``/``PERS``, ``TASK PERS``)
  is global: every module of the task sees it;
- ``LOCAL`` data is seen only in its own module, where it hides global data of the same
  name;
- routine data is seen only in its routine, where it hides both;
- a persistent (``PERS``, ``TASK PERS``) declared in several modules is one variable.
  olp-compensate takes the first declaration with a value, in the order the modules are
  given (the order the controller loads them), and treats the others as that variable.

This module holds those scope rules (:class:`TaskScope`) and finds the ``LOCAL`` names of a
module, which the parsed :class:`Program` does not carry; :func:`~.semantics.resolve_task`
resolves the targets with them.
"""

from __future__ import annotations

import re

from ..targets import Program

__all__ = ["local_data_names", "TaskScope"]

# on the lower-cased text; a match inside a comment or a string is skipped afterwards
_LOCAL_DECLARATION = re.compile(
    r"local\s+(?:const|pers|var)\s+[a-z_][a-z0-9_]*\s+([a-z_][a-z0-9_]*)")


def local_data_names(program: Program) -> frozenset[str]:
    """Lower-case names of the module-level data ``program`` declares ``LOCAL`` (RAPID;
    empty for other dialects). ``LOCAL`` is allowed at module level only, so every such
    declaration is module data. (One lower-casing and a literal search: a module of
    50,000 targets without LOCAL costs a few milliseconds.)"""
    if program.dialect != "rapid":
        return frozenset()
    text = program.text.lower()
    if "local" not in text:
        return frozenset()
    names = set()
    for m in _LOCAL_DECLARATION.finditer(text):
        at = m.start()
        if at and (text[at - 1].isalnum() or text[at - 1] == "_"):
            continue   # the end of another word (``nolocal``)
        if not _in_comment_or_string(text[text.rfind("\n", 0, at) + 1:at]):
            names.add(m.group(1))
    return frozenset(names)


def _in_comment_or_string(line_before: str) -> bool:
    """Whether the text after ``line_before`` (its line up to there) is inside a RAPID
    comment (``!`` to the end of the line) or a string."""
    quoted = False
    for c in line_before:
        if c == '"':
            quoted = not quoted
        elif c == "!" and not quoted:
            return True
    return quoted


class TaskScope:
    """Name lookup with RAPID rules over the modules of a task; no case: routine data
    first, then the module's LOCAL data, then the task's global data (see
    :mod:`..object_model.task`).

    ``table`` holds every item of a name (all elements of an array) under (lower name,
    owner), ``elements`` each one under (lower name, owner, array index); owner is
    (module, routine) for routine data, (module, None) for LOCAL data, None for global
    data. A global name declared in several modules (one PERS) is the first module's
    declaration with a value; ``aliases`` maps each other declaration (id) to the item it
    names."""

    def __init__(self, modules, local_names):
        self.table: dict = {}      # (lower name, owner) -> items
        self.elements: dict = {}   # (lower name, owner, array index) -> item
        self.aliases: dict = {}    # id(item declared again) -> the declaration used
        self.local_names = local_names
        self.routine_data: set = set()   # lower names declared inside some routine
        table, elements = self.table, self.elements
        home: dict = {}            # lower global name -> the module whose items are used
        later: dict = {}           # lower global name -> {module: items} of other modules
        for m, items in enumerate(modules):
            local = local_names[m]
            for it in items:
                name = it.name
                if name is None:
                    continue
                low = name.lower()
                if it.routine is not None:
                    owner = (m, it.routine)
                    self.routine_data.add(low)
                elif local and low in local:
                    owner = (m, None)
                else:
                    owner = None
                    first = home.setdefault(low, m)
                    if first != m:
                        later.setdefault(low, {}).setdefault(m, []).append(it)
                        continue
                key = (low, owner)
                found = table.get(key)
                if found is None:
                    table[key] = [it]
                else:
                    found.append(it)
                elements[(*key, getattr(it, "array_index", None))] = it
        for low, by_module in later.items():   # declared in several modules: rare
            self._declared_again(low, by_module)

    def _declared_again(self, low: str, by_module: dict) -> None:
        """Keep one declaration of global ``low`` (the first with a value: a tooldata
        declared without one refers to the one declared elsewhere); alias the others."""
        used = self.table[(low, None)]
        candidates = [used, *by_module.values()]
        chosen = next((items for items in candidates if any(
            getattr(it, "defined", True) for it in items)), used)
        if chosen is not used:
            self.table[(low, None)] = chosen
            for it in chosen:
                self.elements[(low, None, getattr(it, "array_index", None))] = it
        for items in candidates:
            if items is chosen:
                continue
            for it in items:
                index = getattr(it, "array_index", None)
                self.aliases[id(it)] = self.elements.get((low, None, index), chosen[0])

    def owner(self, low: str, module: int, routine):
        """The owner under which ``low`` is found from ``routine`` of ``module``."""
        if (routine is not None and low in self.routine_data
                and (low, (module, routine)) in self.table):
            return module, routine
        if low in self.local_names[module]:
            return module, None
        return None

    def get(self, name: str, module: int, routine):
        low = name.lower()
        return self.table.get((low, self.owner(low, module, routine)))
