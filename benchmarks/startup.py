"""Start-up time of the commands against ``python -c "import numpy"``, measured in one run.

Prints, for ``olp-cal --help``, ``olp-fix --version`` and olp-fix on a one-target RAPID
module, the minimum and median wall time of new processes (``--runs``, default 7) and the
ratio to importing numpy. DESIGN.md asks for each command within 2x of importing numpy.

Every command runs once untimed first, which writes the package's bytecode as pip does on
install (see installed.py).

    python benchmarks/startup.py [--runs 7]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from installed import installed_env  # noqa: E402

ONE_TARGET = """MODULE one
  CONST robtarget p1 := [[940,0,1455],[0.70711,0,0.70711,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  PROC main()
    MoveJ p1, v100, fine, tool0;
  ENDPROC
ENDMODULE
"""


def timed(argv: list[str], runs: int, cwd: str, env: dict) -> tuple[float, float]:
    """(min, median) wall time of ``runs`` new processes, s; one untimed run first."""
    subprocess.run(argv, cwd=cwd, capture_output=True, env=env)
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        subprocess.run(argv, cwd=cwd, capture_output=True, env=env)
        times.append(time.perf_counter() - start)
    return min(times), statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7, help="timed runs per command (>= 5)")
    args = parser.parse_args()
    bin_dir = Path(sys.executable).parent
    with tempfile.TemporaryDirectory() as folder:
        Path(folder, "one.mod").write_text(ONE_TARGET)
        subprocess.run([str(bin_dir / "olp-cal"), "nominal", "--robot", "abb_irb2400", "-o",
                        "c.json"], cwd=folder, check=True, capture_output=True)
        cases = [
            ("python -c 'import numpy'", [sys.executable, "-c", "import numpy"]),
            ("olp-cal --help", [str(bin_dir / "olp-cal"), "--help"]),
            ("olp-fix --version", [str(bin_dir / "olp-fix"), "--version"]),
            ("olp-fix one.mod (1 target)", [str(bin_dir / "olp-fix"), "one.mod", "--model",
                                            "c.json", "-q"]),
        ]
        env = installed_env(folder)
        results = [(name, *timed(argv, max(args.runs, 5), folder, env)) for name, argv in cases]
    base_min, base_median = results[0][1], results[0][2]
    print(f"{'command':<30}{'min s':>8}{'median s':>10}{'x numpy (median)':>18}")
    for name, low, median in results:
        print(f"{name:<30}{low:>8.3f}{median:>10.3f}{median / base_median:>18.2f}")
    print(f"(new processes, {max(args.runs, 5)} timed runs each after one untimed; "
          f"numpy min {base_min:.3f} s)")


if __name__ == "__main__":
    main()
