"""``olp-cal simulate``: measurements of a virtual robot with known errors, and its truth."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import DataError
from ..io.atomic import write_text_atomic
from ..io.measurements import write_measurements
from ..io.poses import check_within_limits, read_poses
from ..kinematics.robot import load_robot
from .common import refuse_clashes
from .cal_simulate_camera import add_camera_arguments, run_camera
from ..calibration.simulate import (CYCLIC_KIND, HIDDEN_KINDS, make_virtual_robot,
                                    random_cyclic_error, random_hidden_effect, random_joints,
                                    scaled_effect)

HELP = "write measurements of a virtual robot (random geometric errors) and its truth file"
DEFAULT_EFFECT_SIZE = 5.0
"""An --effect without VALUE moves the measured points by this many times the noise (RMS)."""


def add_arguments(p) -> None:
    p.add_argument("--robot", required=True, help="bundled robot name or path to a URDF")
    p.add_argument("--poses", type=int, help="number of measured poses (random joints)")
    p.add_argument("--joints", metavar="CSV",
                   help="measure at these poses instead of random ones: a CSV with pose, "
                        "q1_deg..qN_deg (e.g. from olp-cal plan)")
    p.add_argument("--noise-mm", type=float, default=0.05, help="measurement noise per axis, mm")
    p.add_argument("--orientation-noise-deg", type=float, metavar="DEG",
                   help="also measure the orientation of the tool frames (columns qw, qx, qy, "
                        "qz; a full-pose device), with this noise per axis, deg")
    p.add_argument("--seed", type=int, default=0, help="random seed (errors and poses)")
    p.add_argument("--points", type=int, default=1, help="measured points on the tool per pose")
    p.add_argument("--length-error-mm", type=float, default=1.0, help="link error size, mm")
    p.add_argument("--angle-error-deg", type=float, default=0.1, help="axis/zero error size, deg")
    p.add_argument("--device-distance-m", type=float, default=2.0, help="device distance, m")
    p.add_argument("--effect", action="append", default=[], metavar="KIND[:JOINT[:VALUE[:ORDER]]]",
                   help="hide a non-geometric effect (repeatable): KIND one of "
                        f"{', '.join(HIDDEN_KINDS + (CYCLIC_KIND,))}; JOINT 1-based (empty: random; none for "
                        "thermal_expansion); VALUE in SI (c rad/N.m, harmonic or cyclic amplitude rad, "
                        "backlash gap rad, alpha 1/K, scale rad/rad; empty: sized to move the "
                        f"measured point by {DEFAULT_EFFECT_SIZE:g}x the noise RMS); ORDER 1-3 "
                        "for gear_harmonic, any for cyclic_error (default random, 5-40)")
    p.add_argument("--payloads", metavar="KG[,KG...]",
                   help="payload per pose, drawn from the list (column payload_kg)")
    p.add_argument("--temperatures", metavar="C[,C...]|LO:HI",
                   help="temperature per pose, drawn from the list, or a ramp LO:HI over the "
                        "session (columns temperature_c and time_s, one pose a minute)")
    p.add_argument("--repeats", type=int, default=0,
                   help="measure the first K poses once more (same pose id: a noise floor)")
    p.add_argument("-o", "--output", required=True, help="measurement CSV to write")
    p.add_argument("--truth", help="truth JSON to write (true errors, device pose, tools, effects)")
    add_camera_arguments(p)


def _numbers(text: str, option: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise DataError(f"{option}: expected comma-separated numbers, got '{text}'") from None
    if not values or not all(np.isfinite(values)):
        raise DataError(f"{option}: expected comma-separated numbers, got '{text}'")
    return values


def per_pose_temperatures(text: str, poses: int, rng: np.random.Generator) -> np.ndarray:
    """Temperatures (poses,), deg C, from ``C,C,...`` (random choice) or ``LO:HI`` (ramp)."""
    if ":" in text:
        ends = _numbers(text.replace(":", ","), "--temperatures")
        if text.count(":") != 1 or len(ends) != 2:
            raise DataError(f"--temperatures: expected LO:HI, got '{text}'")
        return np.linspace(ends[0], ends[1], poses)
    return rng.choice(_numbers(text, "--temperatures"), poses)


def parse_effect(spec: str, n_joints: int) -> tuple[str, int | None, float | None, int | None]:
    """(kind, joint 0-based or None, value or None, order or None) of an --effect spec."""
    parts = spec.split(":")
    if len(parts) > 4:
        raise DataError(f"--effect {spec}: expected KIND[:JOINT[:VALUE[:ORDER]]]")
    kind = parts[0].strip()
    if kind not in HIDDEN_KINDS + (CYCLIC_KIND,):
        raise DataError(f"--effect {spec}: unknown effect kind '{kind}' (known: "
                        f"{', '.join(HIDDEN_KINDS)})")
    joint_text = parts[1].strip() if len(parts) > 1 else ""
    joint = None
    if kind == "thermal_expansion":
        if joint_text not in ("", "none", "-"):
            raise DataError(f"--effect {spec}: thermal_expansion acts on the whole arm, give "
                            f"no joint (thermal_expansion::VALUE)")
    elif joint_text:
        try:
            joint = int(joint_text) - 1
        except ValueError:
            raise DataError(f"--effect {spec}: joint '{joint_text}' is not a number") from None
        if not 0 <= joint < n_joints:
            raise DataError(f"--effect {spec}: joint {joint + 1} is out of range (the robot "
                            f"has joints 1..{n_joints})")
    value = None
    if len(parts) > 2 and parts[2].strip():
        try:
            value = float(parts[2])
        except ValueError:
            raise DataError(f"--effect {spec}: value '{parts[2]}' is not a number") from None
    order = None
    if len(parts) > 3 and parts[3].strip():
        text = parts[3].strip()
        if kind == CYCLIC_KIND and text.isdigit() and int(text) >= 1:
            return kind, joint, value, int(text)
        if kind != "gear_harmonic" or text not in ("1", "2", "3"):
            raise DataError(f"--effect {spec}: ORDER is 1, 2 or 3 for gear_harmonic, any "
                            f"positive whole number for cyclic_error, and only for those")
        order = int(parts[3])
    return kind, joint, value, order


@dataclass
class _Poses:
    """The measured poses in order (repeats appended): joints (m, n) in the robot's units
    as random_joints gives them, their ids (None: numbered by the writer), and per pose the
    payload (kg), temperature (deg C) and time (s), None when not simulated."""

    joints: np.ndarray
    pose_ids: list[str] | None
    payload: np.ndarray | None
    temperature: np.ndarray | None
    time_s: np.ndarray | None


def _check_arguments(args) -> None:
    """:class:`DataError` for counts and noises out of range."""
    if (args.poses is None) == (args.joints is None):
        raise DataError("give either --poses N (random joints) or --joints poses.csv")
    if ((args.poses is not None and args.poses < 1) or args.noise_mm < 0 or args.points < 1
            or args.repeats < 0):
        raise DataError("--poses and --points must be positive, --noise-mm and --repeats "
                        "not negative")
    if args.orientation_noise_deg is not None and not args.orientation_noise_deg >= 0:
        raise DataError(f"--orientation-noise-deg must not be negative, got "
                        f"{args.orientation_noise_deg}")


def _conditions(args, effect_rng) -> tuple:
    """(payload kg, temperature deg C, time s) per pose, each None when not asked for."""
    payload = temperature = time_s = None
    if args.payloads:
        payload = effect_rng.choice(_numbers(args.payloads, "--payloads"), args.poses)
        if np.any(payload < 0):
            raise DataError("--payloads: a payload cannot be negative")
    if args.temperatures:
        temperature = per_pose_temperatures(args.temperatures, args.poses, effect_rng)
        time_s = 60.0 * np.arange(args.poses)
    return payload, temperature, time_s


def _hidden_effects(args, robot, virtual, specs, joints, effect_rng, payload,
                    temperature) -> list:
    """The hidden effects asked for with --effect, drawn from ``effect_rng`` and sized to
    the noise unless given a value."""
    conditions = {"payload_kg": payload, "temperature_c": temperature}
    hidden = []
    for (kind, joint, value, order), spec in zip(specs, args.effect):
        if kind == "thermal_expansion" and temperature is None:
            raise DataError(f"--effect {spec}: thermal_expansion needs --temperatures")
        if kind == CYCLIC_KIND:
            effect = random_cyclic_error(robot, effect_rng, joint=joint,
                                         orders=(order, order) if order else (5, 40))
        else:
            effect = random_hidden_effect(robot, effect_rng, joints, kind=kind, joint=joint)
        if order is not None and kind != CYCLIC_KIND:
            effect = replace(effect, order=order)
        if kind == "thermal_expansion":
            effect = replace(effect, reference_temperature_c=20.0)
        if value is not None:
            effect = replace(effect, value=value)
        else:
            size = DEFAULT_EFFECT_SIZE * max(args.noise_mm, 0.05) * 1e-3
            effect = scaled_effect(virtual, effect, joints, size, **conditions)
        hidden.append(effect)
    return hidden


def _repeated(poses: _Poses, repeats: int) -> _Poses:
    """``poses`` with the first ``repeats`` measured again at the end (times continue)."""
    n = len(poses.joints)
    k = min(repeats, n)
    order_ = np.concatenate([np.arange(n), np.arange(k)])
    ids = poses.pose_ids if poses.pose_ids is not None else [str(i + 1) for i in range(n)]

    def again(a):
        return None if a is None else a[order_]
    return _Poses(poses.joints[order_], [ids[i] for i in order_], again(poses.payload),
                  again(poses.temperature),
                  None if poses.time_s is None else 60.0 * np.arange(len(order_)))


def _notes(args, robot, orientation_noise, hidden) -> list[str]:
    """The measurement CSV's ``#`` lines."""
    notes = [f"# robot: {robot.name}", f"# virtual robot seed {args.seed}, "
             f"noise {args.noise_mm} mm per axis"]
    if orientation_noise is not None:
        notes.append(f"# orientation (qw, qx, qy, qz) of each tool frame, noise "
                     f"{args.orientation_noise_deg} deg per axis")
    if hidden:
        notes.append("# hidden effects: " + ", ".join(e.label for e in hidden)
                     + " (see the truth file)")
    return notes


def run(args) -> int:
    if args.camera:
        return run_camera(args)
    refuse_clashes([("--joints", args.joints), ("--robot", args.robot)],
                   [("-o", args.output), ("--truth", args.truth)])
    _check_arguments(args)
    robot = load_robot(args.robot)
    planned = None
    if args.joints is not None:
        planned = read_poses(args.joints, [j.unit for j in robot.joints])
        check_within_limits(planned, robot)
        args.poses = len(planned.joints)
    specs = [parse_effect(s, robot.n_joints) for s in args.effect]
    virtual = make_virtual_robot(robot, args.seed, args.length_error_mm * 1e-3,
                                 np.radians(args.angle_error_deg), args.points,
                                 args.device_distance_m)
    rng = np.random.default_rng(args.seed + 1_000_003)
    joints = random_joints(robot, args.poses, rng) if planned is None else planned.joints
    effect_rng = np.random.default_rng(args.seed + 2_000_003)
    payload, temperature, time_s = _conditions(args, effect_rng)
    hidden = _hidden_effects(args, robot, virtual, specs, joints, effect_rng, payload,
                             temperature)
    virtual = replace(virtual, effects=tuple(hidden))
    poses = _Poses(joints, None if planned is None else planned.pose_ids, payload,
                   temperature, time_s)
    if args.repeats:
        poses = _repeated(poses, args.repeats)
    orientation_noise = (None if args.orientation_noise_deg is None
                         else np.radians(args.orientation_noise_deg))
    meas = virtual.measure(poses.joints, args.noise_mm * 1e-3, rng, payload_kg=poses.payload,
                           temperature_c=poses.temperature, time_s=poses.time_s,
                           pose_ids=poses.pose_ids, orientation_noise_rad=orientation_noise)
    write_measurements(args.output, meas, [j.unit for j in robot.joints],
                       _notes(args, robot, orientation_noise, hidden))
    if args.truth:
        write_text_atomic(args.truth, virtual.to_json())
    effects = "".join(f"; hidden {e.label} = {e.value:.4g}" for e in hidden)
    print(f"wrote {meas.n_rows} measured {'frames' if orientation_noise is not None else 'points'}"
          f" ({args.poses} poses, {args.points} per pose"
          f"{f', {args.repeats} repeated' if args.repeats else ''}) to {args.output}"
          + (f", truth to {args.truth}" if args.truth else "") + effects)
    return 0
