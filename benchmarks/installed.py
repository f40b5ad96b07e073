"""The environment a benchmark runs a command in: as an installed tool runs.

pip writes a package's bytecode when it installs it; a run where PYTHONDONTWRITEBYTECODE
is set and no bytecode exists (an editable install in such a shell) compiles the package
from source every time, about 0.1 s of each olp-fix. The commands are therefore run with
their bytecode written to a folder of the benchmark's (``PYTHONPYCACHEPREFIX``) by an
untimed first run, whatever the shell says.
"""

from __future__ import annotations

import os
from pathlib import Path


def installed_env(folder: str | Path) -> dict[str, str]:
    """This process's environment with bytecode written under ``folder``/bytecode."""
    env = dict(os.environ, PYTHONPYCACHEPREFIX=str(Path(folder) / "bytecode"))
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env
