"""Export a calibrated model as a URDF whose joint origins carry the identified geometry.

Link frames keep their nominal relation to the joint axes (inertials, meshes and fixed frames
stay valid); each movable joint's origin is recomputed so that pinocchio, ROS or any URDF
consumer computes the calibrated forward kinematics. Joint zero offsets go into the origin
rotation. Calibrated tool points are added as fixed links ``<tool>_point`` on the flange.
"""

from __future__ import annotations

import io

import numpy as np

from ..calibration.calibration import Calibration
from ..kinematics.model import joint_frames


def _rot_about(axis: np.ndarray, angle: float) -> np.ndarray:
    from ..kinematics.conventions import rotation_from_rotvec
    pose = np.eye(4)
    pose[:3, :3] = rotation_from_rotvec(np.asarray(axis) * angle)
    return pose


def calibrated_urdf(cal: Calibration) -> str:
    """URDF text of the calibrated robot (the nominal URDF with new joint origins)."""
    import yourdfpy

    robot = cal.robot
    urdf = yourdfpy.URDF.load(io.BytesIO(robot.urdf_text.encode("utf-8")), build_scene_graph=False,
                              load_meshes=False, build_collision_scene_graph=False,
                              load_collision_meshes=False)
    zeros = np.zeros(robot.n_joints)
    nominal_frames = joint_frames(cal.model, cal.model.nominal, zeros)
    calibrated_frames = joint_frames(cal.model, cal.values, zeros)
    urdf_frames = robot.joint_frames_at_zero()  # URDF joint (= child link) frames at zero
    theta_index = {}
    for step in cal.model.steps:
        if step.joint is not None and step.rotation:
            theta_index[step.joint] = step.parameter
    by_name = {j.name: j for j in urdf.robot.joints}
    previous = np.eye(4)
    for i, joint in enumerate(robot.joints):
        # URDF frame relative to the model frame before motion, fixed by the nominal chain.
        offset_nom = offset_cal = np.eye(4)
        if i in theta_index:
            k = theta_index[i]
            offset_nom = _rot_about([0, 0, 1], cal.model.nominal[k])
            offset_cal = _rot_about([0, 0, 1], cal.values[k])
        k_i = np.linalg.inv(nominal_frames[i] @ offset_nom) @ urdf_frames[i]
        frame_cal = calibrated_frames[i] @ offset_cal @ k_i
        original = by_name[joint.name].origin
        original = np.eye(4) if original is None else np.asarray(original)
        fixed_before = joint.parent_T_joint @ np.linalg.inv(original)
        by_name[joint.name].origin = np.linalg.inv(previous @ fixed_before) @ frame_cal
        previous = frame_cal
    for name, tool in cal.tools.items():
        origin = np.eye(4)
        origin[:3, 3] = tool.xyz_m
        link = f"{name}_point"
        urdf.robot.links.append(yourdfpy.Link(name=link))
        urdf.robot.joints.append(yourdfpy.Joint(name=f"{robot.flange_link}-{link}", type="fixed",
                                                parent=robot.flange_link, child=link, origin=origin))
    text = urdf.write_xml_string()
    return text.decode("utf-8") if isinstance(text, bytes) else text
