"""``olp-fix serve`` against the library in one process, measured side by side in one run.

Each pose is a target and its confdata (``--frames``: also its tool and work object, three
matrices of JSON numbers a pose).

Makes, in a temporary folder, a calibration of the IRB 2400 (identified from the bundled
sample measurements) and ``--poses`` reachable targets (default 10,000; random in-range
joints of the nominal arm, away from the wrist singularity) with a tool and a work object,
each with its confdata. Then, ``--repeats`` times (default 3, the best kept), compensates
them in batches of ``--batch`` (default 100):

- through the library in this process: ``compensate_poses`` per batch (the peer);
- over the JSON-lines pipe of one ``olp-fix serve`` process (a request, then its answer);
- over HTTP to ``olp-fix serve --http 127.0.0.1:0`` (one kept-alive connection);

and prints the times and the ratios to the library (targets: pipe <= 1.5x, HTTP <= 2x).
The service and these clients read and write JSON with orjson where it is installed
(``pip install olp-compensate[service]``), else with the standard library (the line says
which).
Every answer is checked against the library's numbers (pose to 1e-12 m, status).

Then ``--clients`` (default 20) HTTP clients, each on its own connection, send batches for
``--seconds`` (default 10; the issue's figure is 60) and every answer is compared with
the one the service's own code gives in this process (the same JSON): it prints the
requests made, the failed requests and the differing answers (targets: none).

Run: ``python benchmarks/service.py [--poses 10000] [--batch 100] [--seconds 10]``.
Exit code 0; 1 when an answer differs or a request fails.
"""

from __future__ import annotations

import argparse
import http.client
import json
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from service_client import HttpService, PipeService  # noqa: E402

from olp_compensate.service import codec  # noqa: E402


WORK_DEG = np.array([[-60, 60], [-20, 50], [-20, 40], [-90, 90], [30, 100], [-90, 90]])
"""Controller joints of the targets (deg): a cell's working region, off the wrist
singularity."""


def make_poses(comp, count: int, rng, frames: bool = False) -> list[dict]:
    """Request poses (mm) the nominal arm reaches at random joints of :data:`WORK_DEG`,
    keeping the first ``count`` the calibrated arm reaches too (a program's targets)."""
    from olp_compensate import compensate_poses

    robot = comp.robot
    q = np.radians(rng.uniform(WORK_DEG[:, 0], WORK_DEG[:, 1], size=(count * 2, 6)))
    q[:, 4] *= rng.choice([-1.0, 1.0], size=len(q))
    tool = np.array([[1, 0, 0, 0.05], [0, 1, 0, 0], [0, 0, 1, 0.15], [0, 0, 0, 1]])
    wobj = np.array([[0, -1, 0, 0.3], [1, 0, 0, -0.1], [0, 0, 1, 0.2], [0, 0, 0, 1]])
    q_urdf = robot.joints_from_controller(q)
    base_T_tcp = comp.nominal_flange(q_urdf) @ tool
    targets = np.linalg.inv(wobj) @ base_T_tcp
    config = comp.confdata(q_urdf)
    reached = compensate_poses(comp, targets, tool, wobj, config).success
    targets, config = targets[reached][:count], config[reached][:count]
    mm = np.diag([1e3, 1e3, 1e3, 1.0])
    def in_mm(a):
        return (mm @ a @ np.linalg.inv(mm)).tolist()
    if not frames:      # the same targets in the base frame, for the flange
        return [{"target": in_mm(wobj @ t @ np.linalg.inv(tool)),
                 "config": [int(c) for c in cf]} for t, cf in zip(targets, config)]
    return [{"target": in_mm(t), "tool": in_mm(tool), "wobj": in_mm(wobj),
             "config": [int(c) for c in cf]} for t, cf in zip(targets, config)]


def library_batches(comp, batches: list[list[dict]]):
    """compensate_poses of each batch (m); returns (seconds, results)."""
    from olp_compensate import compensate_poses

    arrays = []
    for batch in batches:
        def metres(key):
            a = np.array([p.get(key, np.eye(4)) for p in batch], dtype=float)
            a[:, :3, 3] *= 1e-3
            return a
        arrays.append((metres("target"), metres("tool"), metres("wobj"),
                       np.array([p["config"] for p in batch])))
    started = time.perf_counter()
    results = [compensate_poses(comp, t, tool, wobj, conf) for t, tool, wobj, conf in arrays]
    return time.perf_counter() - started, results


def check(answers: list[dict], results) -> int:
    """Answers that differ from the library's (pose to 1e-12 m, status)."""
    bad = 0
    for answer, result in zip(answers, results):
        for got, pose, status in zip(answer["result"]["poses"], result.poses, result.status):
            p = np.array(got["pose"])
            p[:3, 3] *= 1e-3
            if got["status"] != status or (
                    status in ("ok", "singular") and not np.allclose(p, pose, atol=1e-12)):
                bad += 1
    return bad


def over_pipe(root: Path, batches) -> tuple[float, list[dict]]:
    service = PipeService(root)
    try:
        service.call("compensate_poses", {"calibration": "calib.json", "poses": batches[0]})
        started = time.perf_counter()
        answers = [service.call("compensate_poses", {"calibration": "calib.json",
                                                     "poses": b}, k)
                   for k, b in enumerate(batches)]
        return time.perf_counter() - started, answers
    finally:
        service.close()


def over_http(service: HttpService, batches) -> tuple[float, list[dict]]:
    connection = http.client.HTTPConnection("127.0.0.1", service.port, timeout=60)
    def call(k, batch):
        body = codec.dumps({"jsonrpc": "2.0", "method": "compensate_poses", "id": k,
                            "params": {"calibration": "calib.json", "poses": batch}})
        connection.request("POST", "/rpc", body, {"Content-Type": "application/json"})
        return codec.loads(connection.getresponse().read())
    try:
        call(0, batches[0])
        started = time.perf_counter()
        answers = [call(k, b) for k, b in enumerate(batches)]
        return time.perf_counter() - started, answers
    finally:
        connection.close()


def concurrent(service: HttpService, root: Path, batches, clients: int, seconds: float):
    """(requests, failed, differing) of ``clients`` clients for ``seconds``."""
    from olp_compensate.service.calls import Service
    from olp_compensate.service.jsonrpc import handle

    local = Service(root)
    bodies = [json.dumps({"jsonrpc": "2.0", "method": "compensate_poses", "id": k,
                          "params": {"calibration": "calib.json", "poses": b}}).encode()
              for k, b in enumerate(batches[:clients])]
    expected = [json.loads(handle(local, body)) for body in bodies]
    counts = {"requests": 0, "failed": 0, "differing": 0}
    lock = threading.Lock()
    stop = time.monotonic() + seconds

    def client(k: int) -> None:
        connection = http.client.HTTPConnection("127.0.0.1", service.port, timeout=120)
        j = k
        while time.monotonic() < stop:
            j = (j + 1) % len(bodies)
            try:
                connection.request("POST", "/rpc", bodies[j],
                                   {"Content-Type": "application/json"})
                response = connection.getresponse()
                ok = response.status == 200
                answer = json.loads(response.read()) if ok else None
            except (OSError, http.client.HTTPException, ValueError) as exc:
                ok, answer = False, None
                print(f"  client {k}: {type(exc).__name__}: {exc}", file=sys.stderr)
                connection.close()
                connection = http.client.HTTPConnection("127.0.0.1", service.port,
                                                        timeout=120)
            with lock:
                counts["requests"] += 1
                counts["failed"] += not ok
                counts["differing"] += ok and answer != expected[j]
        connection.close()

    threads = [threading.Thread(target=client, args=(k,)) for k in range(clients)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=seconds + 300)
    return counts


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=10_000)
    parser.add_argument("--batch", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--clients", type=int, default=20)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--frames", action="store_true",
                        help="each pose with its tool and work object (3 matrices a pose)")
    args = parser.parse_args()
    from olp_compensate import Compensator, read_calibration

    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        subprocess.run([sys.executable, "-m", "olp_compensate.cli.cal", "identify",
                        str(ROOT / "samples" / "irb2400_measurements.csv"), "--robot",
                        "abb_irb2400", "-o", str(root / "calib.json")], check=True,
                       capture_output=True)
        comp = Compensator(read_calibration(root / "calib.json"))
        poses = make_poses(comp, args.poses, np.random.default_rng(0), args.frames)
        batches = [poses[k:k + args.batch] for k in range(0, len(poses), args.batch)]
        web = HttpService(root)
        try:
            best = {"library": np.inf, "pipe": np.inf, "http": np.inf}
            bad = 0
            for _ in range(args.repeats):
                t_lib, results = library_batches(comp, batches)
                t_pipe, pipe_answers = over_pipe(root, batches)
                t_http, http_answers = over_http(web, batches)
                bad += check(pipe_answers, results) + check(http_answers, results)
                for key, t in (("library", t_lib), ("pipe", t_pipe), ("http", t_http)):
                    best[key] = min(best[key], t)
            n = len(poses)
            what = "target, tool, wobj, config" if args.frames else "target, config"
            print(f"{n} poses ({what}) in batches of {args.batch}, best of "
                  f"{args.repeats}, JSON by {codec.NAME}:")
            for key, target in (("library", None), ("pipe", 1.5), ("http", 2.0)):
                ratio = best[key] / best["library"]
                print(f"  {key:8s} {best[key]:7.3f} s  {best[key] / n * 1e6:7.1f} us/pose  "
                      f"{ratio:5.2f}x the library" + (f" (target <= {target}x)" if target
                                                      else ""))
            print(f"  answers differing from the library's: {bad}")
            counts = concurrent(web, root, batches, args.clients, args.seconds)
            print(f"{args.clients} HTTP clients for {args.seconds:g} s: {counts['requests']} "
                  f"requests, {counts['failed']} failed, {counts['differing']} answers "
                  f"differing from the library's")
        finally:
            web.close()
    return 1 if bad or counts["failed"] or counts["differing"] else 0


if __name__ == "__main__":
    sys.exit(main())
