"""The wheel ships robots/ and grammars/ and an installed package finds them."""

import subprocess
import sys
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _share_dependencies(python: Path) -> None:
    """Make the running environment's site-packages (numpy, lark, ...) importable by the
    venv of ``python``, behind its own; .pth files found there are not run, so an editable
    install of this project in the running environment stays invisible."""
    probe = "import sysconfig; print(sysconfig.get_paths()['purelib'])"
    purelib = subprocess.run([str(python), "-c", probe], check=True, capture_output=True,
                             text=True).stdout.strip()
    dirs = [p for p in sys.path if p.rstrip("/").endswith(("site-packages", "dist-packages"))]
    (Path(purelib) / "_test_deps.pth").write_text("".join(d + "\n" for d in dirs))


@pytest.mark.slow
def test_wheel_ships_robots_and_grammars(tmp_path):
    subprocess.run([sys.executable, "-m", "build", "--wheel", "--outdir",
                    str(tmp_path / "dist"), str(ROOT)], check=True, capture_output=True)
    wheel = next((tmp_path / "dist").glob("*.whl"))
    env_dir = tmp_path / "venv"
    # an isolated venv (the base interpreter may have no numpy: /usr/bin/python3 on a fresh
    # Debian); the dependencies come from the environment running the tests, appended to
    # sys.path by a .pth file, after the venv's own site-packages where the wheel goes
    venv.create(env_dir, with_pip=True, system_site_packages=False)
    python = env_dir / "bin" / "python"
    _share_dependencies(python)
    subprocess.run([str(python), "-m", "pip", "install", "--no-deps", "--force-reinstall", "-q",
                    str(wheel)], check=True, capture_output=True)
    probe = (
        "import olp_compensate, pathlib\n"
        "from importlib import resources\n"
        "assert 'site-packages' in olp_compensate.__file__, olp_compensate.__file__\n"
        "robots = sorted(p.name for p in resources.files('olp_compensate.robots').iterdir())\n"
        "grammars = sorted(p.name for p in resources.files('olp_compensate.grammars').iterdir())\n"
        "from olp_compensate.kinematics.robot import load_robot\n"
        "from olp_compensate.programs.languages import languages\n"
        "for language in languages():\n"
        "    __import__(f'olp_compensate.programs.{language.name}.reader')\n"
        "print(load_robot('abb_irb2400').n_joints, robots, grammars)\n")
    out = subprocess.run([str(python), "-c", probe], check=True, capture_output=True, text=True,
                         cwd=tmp_path).stdout
    assert out.startswith("6 ")
    assert "abb_irb2400.robot.json" in out and "ur5e.robot.json" in out and "README.md" in out
    assert ".urdf" not in out.split("] [")[0]   # robots are records; URDFs are generated
    assert "README.md" in out.split("] [")[-1]  # the grammars folder ships


def test_every_package_folder_ships():
    """pyproject.toml lists its packages one by one: a folder added to the tree must be added
    there, or the wheel leaves it out (a language folder, a subpackage)."""
    import tomllib

    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
                 ["packages"])
    folders = {".".join(p.parent.relative_to(ROOT).parts)
               for p in (ROOT / "olp_compensate").rglob("__init__.py")}
    assert folders <= listed, sorted(folders - listed)


def _readme_command(after: str) -> str:
    """The indented command line that follows the paragraph starting with ``after``."""
    text = (ROOT / "README.md").read_text()
    block = text[text.index(after):]
    return next(ln.strip() for ln in block.splitlines() if ln.startswith("    ") and ln.strip())


def test_ci_runs_exactly_the_readmes_test_command():
    command = _readme_command("Run the tests")
    assert command.startswith("python3 -m venv .venv && .venv/bin/")   # no active venv needed
    ci = [ln for ln in (ROOT / ".ci" / "run").read_text().splitlines()
          if ln.strip() and not ln.startswith("#")]
    assert ci[-1] == command


def _console_lines() -> list[str]:
    """The commands of the README's worked example (``$ olp-...`` lines)."""
    text = (ROOT / "README.md").read_text()
    example = text[text.index("## Worked example"):]
    example = example[:example.index("\n## ", 5)]
    return [ln[2:].split("  #")[0].strip() for ln in example.splitlines()
            if ln.startswith("$ olp-")]


@pytest.mark.slow
def test_the_readme_commands_run_as_written_in_a_fresh_folder(tmp_path):
    """The set-up command (after its install steps) and the worked example, in a fresh
    folder holding only the shipped samples, with the installed olp-cal and olp-fix."""
    import shlex
    import shutil

    shutil.copytree(ROOT / "samples", tmp_path / "samples")
    bin_dir = Path(sys.executable).parent
    setup = _readme_command("Run the main job")
    steps = [s.strip() for part in setup.split("&&") for s in part.split(";")]
    steps = [s for s in steps if s.startswith(("olp-cal", "olp-fix"))]
    assert len(steps) == 4
    expected = {"olp-cal": 0, "olp-fix": 2}
    for step in steps + _console_lines():
        words = shlex.split(step)
        done = subprocess.run([str(bin_dir / words[0])] + words[1:], cwd=tmp_path,
                              capture_output=True, text=True, timeout=600)
        want = expected[words[0]] if step in steps else 0
        assert done.returncode == want, (step, done.stderr)
        assert "Traceback" not in done.stderr
    assert (tmp_path / "samples" / "cell_a_compensated.mod").exists()
    assert (tmp_path / "cell_a_report.csv").exists() and (tmp_path / "cell_b_report.csv").exists()
