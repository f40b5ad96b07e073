"""A small loopback RTDE server that the real ur-rtde client can talk to, for tests.

It speaks the Real-Time Data Exchange protocol version 2 as Universal Robots documents it
("Real-Time Data Exchange (RTDE) Guide", UR support article 22229): every package is a
big-endian header ``uint16 size`` (header included) + ``uint8 type`` followed by a payload.

Handled requests and the replies sent:

=====  ====================================  =================================================
type   request payload                       reply payload
=====  ====================================  =================================================
'V'    uint16 protocol version               uint8 accepted (1 for version 1 or 2)
'v'    (none)                                uint32 major, minor, bugfix, build
'O'    double frequency, "name,name,..."     uint8 recipe id, "TYPE,TYPE,..." (NOT_FOUND for
                                             unknown names)
'I'    "name,name,..."                       uint8 recipe id, "TYPE,..." (NOT_FOUND for each:
                                             this peer takes no inputs)
'S'    (none)                                uint8 accepted; then 'U' data packages stream
'P'    (none)                                uint8 accepted; streaming stops
=====  ====================================  =================================================

Streamed ``'U'`` packages carry ``uint8 recipe id`` then each requested output packed by its
type: ``timestamp`` is the time since the peer started (s), ``actual_q`` and ``target_q`` are
the joints set with :meth:`RtdePeer.set_joints` (rad), everything else is zero.

What ur-rtde 1.6.5's receive interface sends, in order: 'V' (protocol version 2), 'v'
(controller version; major > 3 means e-Series, default 500 Hz, else 125 Hz), 'O' (its
frequency and the variables passed, or by default a 58-variable recipe: timestamp, target_*,
actual_*, modes, voltages, bits, payload, output registers 2, 12-19...), then 'S'. It never
sends 'I'. A NOT_FOUND type makes it raise "The following variables was not found by the
controller", so the peer types every variable of the RTDE guide it may ask for.

ur-rtde's ``RTDEReceiveInterface(hostname, frequency=-1.0, variables=[], verbose=False,
use_upper_range_registers=False, rt_priority=0)`` (version 1.6.5) has no port argument and
always connects to port 30004, so the peer listens on ``<loopback address>:30004``; on Linux
any 127.x.y.z is loopback, and the peer picks a random one so that parallel test runs do not
collide. Only loopback addresses are accepted.

The server runs in a separate process (``spawn``), not a thread: ur-rtde's constructor holds
Python's GIL while it negotiates, so a peer thread in the client's process could never answer.
Every loop is bounded in time: the server process stops by itself after ``lifetime_s``.
"""

from __future__ import annotations

import multiprocessing
import queue
import random
import select
import socket
import struct
import time

RTDE_PORT = 30004

# Output variables of the RTDE guide and their types (the subset any receive client asks for).
_VECTOR6D = ("target_q target_qd target_qdd target_current target_moment actual_q actual_qd "
             "actual_current joint_control_output actual_TCP_pose actual_TCP_speed "
             "actual_TCP_force target_TCP_pose target_TCP_speed joint_temperatures "
             "actual_joint_voltage payload_inertia ft_raw_wrench actual_current_window "
             "actual_current_as_torque joint_position_deviation_ratio").split()
_DOUBLE = ("timestamp actual_execution_time speed_scaling target_speed_fraction actual_momentum "
           "actual_main_voltage actual_robot_voltage actual_robot_current "
           "standard_analog_input0 standard_analog_input1 standard_analog_output0 "
           "standard_analog_output1 io_current tool_analog_input0 tool_analog_input1 "
           "tool_output_current tool_temperature tcp_force_scalar speed_scaling_combined "
           "payload collision_detection_ratio").split()
_VECTOR3D = "actual_tool_accelerometer elbow_position elbow_velocity payload_cog".split()
_UINT32 = ("runtime_state robot_status_bits safety_status_bits analog_io_types tool_mode "
           "tool_analog_input_types output_bit_registers0_to_31 output_bit_registers32_to_63 "
           "script_control_line euromap67_input_bits euromap67_output_bits").split()
_INT32 = "robot_mode safety_mode safety_status tool_output_voltage".split()
_UINT64 = "actual_digital_input_bits actual_digital_output_bits".split()

OUTPUT_TYPES: dict[str, str] = {}
for _names, _type in ((_VECTOR6D, "VECTOR6D"), (_DOUBLE, "DOUBLE"), (_VECTOR3D, "VECTOR3D"),
                      (_UINT32, "UINT32"), (_INT32, "INT32"), (_UINT64, "UINT64")):
    OUTPUT_TYPES.update(dict.fromkeys(_names, _type))
OUTPUT_TYPES["joint_mode"] = "VECTOR6INT32"
for _i in range(48):
    OUTPUT_TYPES[f"output_int_register_{_i}"] = "INT32"
    OUTPUT_TYPES[f"output_double_register_{_i}"] = "DOUBLE"
for _i in range(64, 128):
    OUTPUT_TYPES[f"output_bit_register_{_i}"] = "BOOL"

_PACK = {"DOUBLE": ">d", "VECTOR3D": ">3d", "VECTOR6D": ">6d", "UINT32": ">I", "INT32": ">i",
         "UINT64": ">Q", "VECTOR6INT32": ">6i", "BOOL": ">B", "UINT8": ">B"}


def _package(kind: bytes, payload: bytes = b"") -> bytes:
    return struct.pack(">HB", 3 + len(payload), kind[0]) + payload


class RtdePeer:
    """A loopback RTDE controller stand-in, served from a child process.

    Parameters
    ----------
    host : loopback address to listen on; None picks a random free 127.x.y.z (Linux), or
        127.0.0.1 where only that one exists.
    port : TCP port (30004 is the only one ur-rtde's receive interface uses).
    frequency_hz : upper bound on the streaming rate (the client's requested rate is used
        when lower).
    lifetime_s : the server process stops by itself after this long.
    controller_version : (major, minor, bugfix, build) answered to 'v'.
    """

    def __init__(self, host: str | None = None, port: int = RTDE_PORT,
                 frequency_hz: float = 125.0, lifetime_s: float = 30.0,
                 controller_version: tuple[int, int, int, int] = (5, 11, 0, 0)):
        if host is not None and not host.startswith("127."):
            raise ValueError(f"RtdePeer listens on loopback addresses only, not {host!r}")
        ctx = multiprocessing.get_context("spawn")
        self.port = port
        self._joints = ctx.Array("d", 6)
        self._streaming = ctx.Event()
        self._streaming.set()
        self._stop = ctx.Event()
        self._events = ctx.Queue()
        self._requested: list[str] = []
        self._commands: list[str] = []
        self._process = ctx.Process(
            target=_run_peer, name="rtde-peer", daemon=True,
            args=(host, port, frequency_hz, lifetime_s, tuple(controller_version),
                  self._joints, self._streaming, self._stop, self._events))
        self.host: str | None = None

    # -- control from the test ---------------------------------------------------------------
    def start(self, timeout_s: float = 20.0) -> "RtdePeer":
        """Start the server process and wait until it listens (or raise OSError)."""
        self._process.start()
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                kind, value = self._events.get(timeout=0.1)
                break
            except queue.Empty:
                if not self._process.is_alive() or time.monotonic() > deadline:
                    self.close()
                    raise OSError(f"RtdePeer did not start within {timeout_s} s (exit code "
                                  f"{self._process.exitcode})") from None
        if kind != "bound":
            self.close()
            raise OSError(value)
        self.host = value
        return self

    def set_joints(self, q_rad) -> None:
        """Set the streamed ``actual_q`` (6 values, rad)."""
        values = [float(v) for v in q_rad]
        if len(values) != 6:
            raise ValueError(f"expected 6 joint values, got {len(values)}")
        with self._joints.get_lock():
            self._joints[:] = values

    def stop_streaming(self) -> None:
        """Keep the connection open but send no more data packages (a stalled controller)."""
        self._streaming.clear()

    def resume_streaming(self) -> None:
        self._streaming.set()

    @property
    def requested_outputs(self) -> list[str]:
        """Output names of the last 'O' (setup outputs) request."""
        self._drain()
        return list(self._requested)

    @property
    def commands(self) -> list[str]:
        """Package types received so far, in order (e.g. ['V', 'v', 'O', 'S'])."""
        self._drain()
        return list(self._commands)

    def close(self) -> None:
        self._stop.set()
        if self._process.is_alive():
            self._process.join(timeout=5.0)
        if self._process.is_alive():
            self._process.terminate()
            self._process.join(timeout=5.0)

    def __enter__(self) -> "RtdePeer":
        return self.start() if self.host is None else self

    def __exit__(self, *exc) -> None:
        self.close()

    def _drain(self) -> None:
        for _ in range(10_000):
            try:
                kind, value = self._events.get_nowait()
            except (queue.Empty, OSError, ValueError):
                return
            if kind == "outputs":
                self._requested = value
            elif kind == "command":
                self._commands.append(value)


def _bind(host: str | None, port: int) -> socket.socket:
    candidates = [host] if host else (
        [f"127.{random.randint(1, 254)}.{random.randint(0, 254)}.{random.randint(1, 254)}"
         for _ in range(8)] + ["127.0.0.1"])
    last_error: OSError | None = None
    for address in candidates:
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            sock.bind((address, port))
            sock.listen(2)
            sock.settimeout(0.1)
            return sock
        except OSError as exc:
            last_error = exc
            sock.close()
    raise OSError(f"RtdePeer could not bind a loopback address on port {port}: {last_error}")


def _run_peer(host, port, frequency_hz, lifetime_s, controller_version, joints, streaming,
              stop, events) -> None:
    """Child-process entry point: bind, report the address, serve until stop or lifetime."""
    try:
        listener = _bind(host, port)
    except OSError as exc:
        events.put(("error", str(exc)))
        return
    events.put(("bound", listener.getsockname()[0]))
    server = _Server(joints, streaming, stop, events, frequency_hz, controller_version)
    deadline = time.monotonic() + lifetime_s
    with listener:
        while not stop.is_set() and time.monotonic() < deadline:
            try:
                conn, _ = listener.accept()
            except (socket.timeout, OSError):
                continue
            with conn:
                try:
                    server.session(conn, deadline)
                except OSError:
                    pass  # client went away; wait for the next one


class _Server:
    """Protocol state of one peer (lives in the child process)."""

    def __init__(self, joints, streaming, stop, events, frequency_hz, controller_version):
        self.joints = joints
        self.streaming_allowed = streaming
        self.stop = stop
        self.events = events
        self.frequency_hz = frequency_hz
        self.controller_version = controller_version
        self.t0 = time.monotonic()

    def session(self, conn: socket.socket, deadline: float) -> None:
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        buffer = b""
        self.recipe: list[str] = []
        self.started = False
        self.period = 1.0 / self.frequency_hz
        next_send = time.monotonic()
        while not self.stop.is_set() and time.monotonic() < deadline:
            wait = max(0.0, min(0.05, next_send - time.monotonic())) if self.started else 0.05
            readable, _, _ = select.select([conn], [], [], wait)
            if readable:
                chunk = conn.recv(4096)
                if not chunk:
                    return
                buffer += chunk
                while len(buffer) >= 3:
                    size, kind = struct.unpack(">HB", buffer[:3])
                    if size < 3 or len(buffer) < size:
                        break
                    payload, buffer = buffer[3:size], buffer[size:]
                    conn.sendall(self.handle(chr(kind), payload))
            now = time.monotonic()
            if self.started and now >= next_send:
                next_send = now + self.period
                if self.streaming_allowed.is_set():
                    conn.sendall(self.data_package(now))

    def handle(self, kind: str, payload: bytes) -> bytes:
        """Reply to one request package."""
        self.events.put(("command", kind))
        if kind == "V":
            (version,) = struct.unpack(">H", payload[:2])
            return _package(b"V", struct.pack(">B", int(version in (1, 2))))
        if kind == "v":
            return _package(b"v", struct.pack(">4I", *self.controller_version))
        if kind == "O":
            (frequency,) = struct.unpack(">d", payload[:8])
            names = [n for n in payload[8:].decode("ascii").split(",") if n]
            self.events.put(("outputs", names))
            if frequency > 0:
                self.period = 1.0 / min(frequency, self.frequency_hz)
            self.recipe = names
            types = [OUTPUT_TYPES.get(n, "NOT_FOUND") for n in names]
            return _package(b"O", b"\x01" + ",".join(types).encode("ascii"))
        if kind == "I":
            names = [n for n in payload.decode("ascii").split(",") if n]
            return _package(b"I", b"\x00" + ",".join(["NOT_FOUND"] * len(names)).encode())
        if kind == "S":
            self.started = True
            return _package(b"S", b"\x01")
        if kind == "P":
            self.started = False
            return _package(b"P", b"\x01")
        message = f"unsupported package type {kind!r}".encode("ascii")
        source = b"rtde_peer"
        return _package(b"M", struct.pack(">B", len(message)) + message
                        + struct.pack(">B", len(source)) + source + struct.pack(">B", 1))

    def data_package(self, now: float) -> bytes:
        """One 'U' package: recipe id 1, then every recipe output packed by its type."""
        with self.joints.get_lock():
            joints = list(self.joints[:])
        parts = [b"\x01"]
        for name in self.recipe:
            kind = OUTPUT_TYPES.get(name)
            if kind is None:
                continue
            if name in ("actual_q", "target_q"):
                parts.append(struct.pack(">6d", *joints))
            elif name == "timestamp":
                parts.append(struct.pack(">d", now - self.t0))
            else:
                count = {"VECTOR3D": 3, "VECTOR6D": 6, "VECTOR6INT32": 6}.get(kind, 1)
                parts.append(struct.pack(_PACK[kind], *([0] * count)))
        return _package(b"U", b"".join(parts))
