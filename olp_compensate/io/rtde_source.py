"""Joint sources for work at the robot: typed from the pendant, or read live over UR RTDE.

A joint source gives the robot's joints at the moment the technician says so:
``capture(ask, say, instruction, commands)`` shows the instruction through ``ask`` and returns
a :class:`JointReading`, or one of ``commands`` (e.g. ``'q'``, ``'done'``) when the technician
typed it instead. ``read()`` (RTDE only) reads without asking.

:class:`RtdeJointSource` is **read-only**: it uses ur-rtde's ``rtde_receive`` and never
imports ``rtde_control``, so it cannot move the robot. ur-rtde's ``RTDEReceiveInterface``
(1.6: ``(hostname, frequency=-1.0, variables=[], verbose=False,
use_upper_range_registers=False, rt_priority=0)``, always port 30004) blocks while holding
Python's GIL, without a timeout, when a controller accepts the connection and does not
answer. So the client runs in a child process that this module can stop: connection refused,
timeouts and a controller that stops streaming each end in an :class:`OlpError` within
``connect_timeout_s`` / ``stall_timeout_s``, never a hang.
"""

from __future__ import annotations

import multiprocessing
import os
import re
import socket
import sys
import time
from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np

from ..errors import DataError, OlpError

RTDE_PORT = 30004
STILL_TOLERANCE_RAD = 1e-4
"""Largest joint spread over the averaged samples of a reading (about 0.1 mm at 1 m)."""

Ask = Callable[[str], str]
Say = Callable[[str], None]


@dataclass(frozen=True)
class JointReading:
    """One joint reading: ``q_rad`` (n,) rad; ``time_s`` Unix time (s, UTC) of the reading;
    ``controller_time_s`` the controller's own clock (s since it started) or None;
    ``spread_rad`` the largest joint change over the averaged samples (0 when typed)."""

    q_rad: np.ndarray
    time_s: float
    controller_time_s: float | None = None
    spread_rad: float = 0.0


class JointSource(Protocol):
    """Where the wizard and the session recorder get joints from."""

    n_joints: int
    description: str

    def capture(self, ask: Ask, say: Say, instruction: str,
                commands: tuple[str, ...] = ()) -> JointReading | str: ...

    def close(self) -> None: ...


def console_ask(prompt: str) -> str:
    """Ask on the terminal: ``prompt`` on stdout, one line from stdin. End of input counts
    as ``q`` (quit). When stdin is not a terminal (a script, a pipe) the answer is echoed,
    so the transcript reads like the session."""
    sys.stdout.write(prompt)
    sys.stdout.flush()
    line = sys.stdin.readline()
    if not line:
        sys.stdout.write("q (end of input)\n")
        return "q"
    answer = line.rstrip("\r\n")
    isatty = getattr(sys.stdin, "isatty", None)
    if not (isatty and isatty()):
        sys.stdout.write(answer + "\n")
    return answer


def console_say(text: str) -> None:
    """Show a line on stdout at once."""
    print(text, flush=True)


def parse_joints_deg(text: str, n_joints: int) -> np.ndarray:
    """Joints typed or pasted from a pendant: ``n_joints`` numbers in degrees, separated by
    spaces, commas or semicolons (brackets allowed). Returns (n,) degrees."""
    fields = [f for f in re.split(r"[\s,;]+", text.strip().strip("[](){}")) if f]
    values = []
    for k, field in enumerate(fields):
        try:
            value = float(field)
        except ValueError:
            raise DataError(f"joint {k + 1}: '{field}' is not a number") from None
        if not np.isfinite(value):
            raise DataError(f"joint {k + 1}: {field} is not a finite number")
        values.append(value)
    if len(values) != n_joints:
        raise DataError(f"expected {n_joints} joint values in degrees (q1 ... q{n_joints}), "
                        f"got {len(values)}")
    return np.array(values)


class TypedJointSource:
    """Joints typed by the technician from the pendant's joint display, in degrees."""

    def __init__(self, n_joints: int = 6, max_attempts: int = 20):
        self.n_joints = n_joints
        self.max_attempts = max_attempts
        self.description = "typed from the pendant"

    def capture(self, ask: Ask, say: Say, instruction: str,
                commands: tuple[str, ...] = ()) -> JointReading | str:
        prompt = (f"{instruction}, then type the joints q1..q{self.n_joints} in degrees as "
                  f"the pendant shows them: ")
        for _ in range(self.max_attempts):
            answer = ask(prompt).strip()
            if answer.lower() in commands:
                return answer.lower()
            try:
                q_deg = parse_joints_deg(answer, self.n_joints)
            except DataError as exc:
                say(f"  {exc}; try again (or type {' / '.join(commands) or 'Ctrl-C'}).")
                continue
            return JointReading(np.radians(q_deg), time.time())
        raise DataError(f"no valid joint entry after {self.max_attempts} attempts")

    def close(self) -> None:
        pass


def _probe(host: str, timeout_s: float) -> None:
    """Fail fast, with a clear message, when nothing answers on host:30004."""
    where = f"{host}:{RTDE_PORT}"
    try:
        socket.create_connection((host, RTDE_PORT), timeout=timeout_s).close()
    except ConnectionRefusedError:
        raise OlpError(f"connection refused by {where}: no RTDE server listens there. Check "
                       f"the robot's IP address, that the controller is on, and that RTDE is "
                       f"enabled (PolyScope: Settings > Security > Services).") from None
    except socket.timeout:
        raise OlpError(f"no answer from {where} within {timeout_s:g} s: check the network "
                       f"cable, the robot's IP address and this computer's subnet.") from None
    except socket.gaierror as exc:
        raise OlpError(f"unknown robot address {host!r} ({exc.strerror})") from None
    except OSError as exc:
        raise OlpError(f"cannot reach {where}: {exc.strerror or exc}") from None


def _worker(host: str, frequency_hz: float, conn, quiet: bool) -> None:
    """Child process: hold the ur-rtde receive interface, answer 'read' requests."""
    if quiet:  # ur-rtde prints progress from C++ to stdout/stderr
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
    try:
        import rtde_receive  # read-only by design: rtde_control is never imported
    except ImportError:
        conn.send(("error", "ur-rtde is not installed: pip install ur-rtde"))
        return
    try:
        receiver = rtde_receive.RTDEReceiveInterface(host, frequency_hz,
                                                     ["timestamp", "actual_q"])
    except Exception as exc:  # ur-rtde raises RuntimeError and boost errors
        conn.send(("error", f"RTDE setup with {host}:{RTDE_PORT} failed: {exc}"))
        return
    conn.send(("ready", None))
    parent = multiprocessing.parent_process()
    while parent is None or parent.is_alive():
        try:
            if not conn.poll(0.5):
                continue
            request = conn.recv()
        except (EOFError, OSError):
            break
        if request == "close":
            break
        try:
            conn.send(("state", (list(receiver.getActualQ()), float(receiver.getTimestamp()),
                                 bool(receiver.isConnected()))))
        except Exception as exc:
            conn.send(("error", f"RTDE read failed: {exc}"))
    os._exit(0)  # skip ur-rtde's slow disconnect; the socket closes with the process


class RtdeJointSource:
    """Read-only live joints from a Universal Robots controller over RTDE (port 30004).

    Parameters
    ----------
    host : controller IP address or name.
    frequency_hz : RTDE output rate asked for (CB3: up to 125 Hz, e-Series 500 Hz).
    connect_timeout_s : limit for reaching the port and finishing the RTDE handshake.
    stall_timeout_s : a reading fails when no new data package arrives for this long.
    samples : data packages averaged per reading.
    quiet : hide ur-rtde's own console output.
    """

    n_joints = 6

    def __init__(self, host: str, frequency_hz: float = 125.0, connect_timeout_s: float = 5.0,
                 stall_timeout_s: float = 1.0, samples: int = 5, quiet: bool = True):
        self.host = host
        self.description = f"UR controller at {host}:{RTDE_PORT} (RTDE)"
        self.stall_timeout_s = stall_timeout_s
        self.samples = max(1, int(samples))
        _probe(host, connect_timeout_s)
        ctx = multiprocessing.get_context("spawn")
        self._conn, child = ctx.Pipe()
        self._process = ctx.Process(target=_worker, args=(host, frequency_hz, child, quiet),
                                    name="olp-rtde-reader", daemon=True)
        self._process.start()
        child.close()
        kind, value = self._receive(connect_timeout_s + 2.0, "finish the RTDE handshake")
        if kind != "ready":
            self.close()
            raise OlpError(value)

    def _receive(self, timeout_s: float, doing: str):
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                if self._conn.poll(0.05):
                    return self._conn.recv()
            except (EOFError, OSError):
                break
            if not self._process.is_alive() and not self._conn.poll(0):
                break
        alive = self._process.is_alive()
        self.close()
        if alive:
            raise OlpError(f"{self.host}:{RTDE_PORT} accepted the connection but did not "
                           f"{doing} within {timeout_s:g} s: is it a UR controller with RTDE "
                           f"enabled?")
        raise OlpError(f"the RTDE reader for {self.host} stopped unexpectedly")

    def _state(self):
        try:
            self._conn.send("read")
        except (OSError, ValueError):
            raise OlpError(f"the connection to {self.host} is closed") from None
        kind, value = self._receive(self.stall_timeout_s + 2.0, "answer")
        if kind != "state":
            raise OlpError(value)
        q, stamp, connected = value
        if not connected:
            raise OlpError(f"lost the RTDE connection to {self.host}:{RTDE_PORT} (the "
                           f"controller closed it); reconnect and read this pose again")
        return np.array(q, dtype=float), stamp

    def read(self) -> JointReading:
        """Average ``samples`` fresh data packages (all newer than the call) into one reading."""
        _, last = self._state()
        qs, stamps = [], []
        deadline = time.monotonic() + self.stall_timeout_s
        while len(qs) < self.samples:
            q, stamp = self._state()
            if stamp != last:
                qs.append(q)
                stamps.append(stamp)
                last = stamp
                deadline = time.monotonic() + self.stall_timeout_s
            elif time.monotonic() > deadline:
                raise OlpError(f"the controller at {self.host} stopped streaming: no new RTDE "
                               f"data for {self.stall_timeout_s:g} s (last controller time "
                               f"{last:.3f} s). Check the robot and the network, then retry.")
            else:
                time.sleep(0.001)
        qs = np.array(qs)
        return JointReading(qs.mean(axis=0), time.time(), float(stamps[-1]),
                            float(np.max(np.ptp(qs, axis=0))))

    def capture(self, ask: Ask, say: Say, instruction: str,
                commands: tuple[str, ...] = ()) -> JointReading | str:
        """Ask for Enter, then read; re-ask while the robot still moves."""
        hint = f" (or type {' / '.join(commands)})" if commands else ""
        for _ in range(20):
            answer = ask(f"{instruction}, then press Enter{hint}: ").strip().lower()
            if answer in commands:
                return answer
            if answer:
                say(f"  Press Enter to read the joints from the robot{hint}.")
                continue
            reading = self.read()
            if reading.spread_rad <= STILL_TOLERANCE_RAD:
                return reading
            say(f"  The robot was still moving ({np.degrees(reading.spread_rad):.3f} deg "
                f"during the reading); let it stand still and press Enter again.")
        raise DataError("no steady joint reading after 20 attempts")

    def close(self) -> None:
        """Stop the reader process (at most about 1 s)."""
        try:
            self._conn.send("close")
        except (OSError, ValueError, AttributeError):
            pass
        process = getattr(self, "_process", None)
        if process is not None and process.pid is not None:
            process.join(timeout=1.0)
            if process.is_alive():
                process.terminate()
                process.join(timeout=1.0)
        if hasattr(self, "_conn"):
            self._conn.close()

    def __enter__(self) -> "RtdeJointSource":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
