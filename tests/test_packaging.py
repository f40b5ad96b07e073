"""The wheel ships robots/ and grammars/ and an installed package finds them."""

import subprocess
import sys
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_wheel_ships_robots_and_grammars(tmp_path):
    subprocess.run([sys.executable, "-m", "build", "--wheel", "--outdir",
                    str(tmp_path / "dist"), str(ROOT)], check=True, capture_output=True)
    wheel = next((tmp_path / "dist").glob("*.whl"))
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=True, system_site_packages=True)
    python = env_dir / "bin" / "python"
    subprocess.run([str(python), "-m", "pip", "install", "--no-deps", "--force-reinstall", "-q",
                    str(wheel)], check=True, capture_output=True)
    probe = (
        "import olp_compensate, pathlib\n"
        "from importlib import resources\n"
        "assert 'site-packages' in olp_compensate.__file__, olp_compensate.__file__\n"
        "robots = sorted(p.name for p in resources.files('olp_compensate.robots').iterdir())\n"
        "grammars = sorted(p.name for p in resources.files('olp_compensate.grammars').iterdir())\n"
        "from olp_compensate.kinematics.robot import load_robot\n"
        "print(load_robot('abb_irb2400').n_joints, robots, grammars)\n")
    out = subprocess.run([str(python), "-c", probe], check=True, capture_output=True, text=True,
                         cwd=tmp_path).stdout
    assert out.startswith("6 ")
    assert "abb_irb2400.urdf" in out and "ur5e.urdf" in out and "abb_irb2400.controller.json" in out
    assert "README.md" in out.split("] [")[-1]  # the grammars folder ships
