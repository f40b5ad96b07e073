"""Gravity load torques from the URDF inertials, computed with pinocchio.

The *load torque* ``tau_j`` is the torque gravity exerts about joint j (N.m): the opposite
of pinocchio's generalized gravity ``g(q)``, which is the torque a drive must deliver to
hold the arm. A joint of stiffness k therefore sags by ``dq = tau / k``. Gravity is
9.81 m/s^2 along the base frame's -z (a floor-mounted robot). A payload is a point mass at
a point given in the flange frame.

Controller axes: where the controller's axes differ from the URDF joints
(``q_urdf = M q_ctrl``, the ABB parallel linkage), torques map by virtual work,
``tau_ctrl = M^T tau_urdf``, and their derivatives as
``dtau_ctrl/dq_ctrl = M^T (dtau_urdf/dq_urdf) M``.
"""

from __future__ import annotations

import numpy as np

from ..kinematics.robot import Robot

_CACHE: dict[tuple[str, int], "GravityModel"] = {}


class GravityModel:
    """Gravity load torques of one robot (state: a private pinocchio model and workspace)."""

    def __init__(self, robot: Robot):
        import pinocchio as pin

        self._pin = pin
        self.robot = robot
        self.model = robot.pinocchio_model.copy()  # private: the payload is set per row
        self.data = self.model.createData()
        ids = robot.pinocchio_joint_ids()
        self._joints = [self.model.joints[i] for i in ids]
        self._idx_v = np.array([j.idx_v for j in self._joints])
        frame = self.model.frames[self.model.getFrameId(robot.flange_link)]
        self._payload_joint = frame.parentJoint
        self._joint_T_flange = frame.placement
        self._bare_inertia = self.model.inertias[self._payload_joint].copy()
        # fast path: the model is exactly the chain, one coordinate per joint, in order
        self._direct = (self.model.nq == self.model.nv == len(self._joints)
                        and [j.idx_q for j in self._joints] == list(range(len(self._joints))))

    def _configuration(self, q_urdf: np.ndarray) -> np.ndarray:
        if self._direct:
            return q_urdf
        config = self._pin.neutral(self.model)
        for joint, value in zip(self._joints, q_urdf):
            if joint.nq == 2:  # continuous joint: (cos, sin)
                config[joint.idx_q:joint.idx_q + 2] = np.cos(value), np.sin(value)
            else:
                config[joint.idx_q] = value
        return config

    def load_torque_urdf(self, q_urdf: np.ndarray, payload_kg: np.ndarray | None = None,
                         payload_point_m: np.ndarray | None = None, derivatives: bool = False):
        """Load torques (m, n), N.m (N for a prismatic joint), for URDF joints (m, n), rad/m;
        with ``derivatives`` also d tau / d q (m, n, n). ``payload_kg`` (m,) sits at
        ``payload_point_m`` (m, 3), flange frame (default the flange origin)."""
        pin = self._pin
        q_urdf = np.atleast_2d(np.asarray(q_urdf, dtype=float))
        m = len(q_urdf)
        n = len(self._joints)
        tau = np.empty((m, self.model.nv))
        dtau = np.empty((m, self.model.nv, self.model.nv)) if derivatives else None
        model, data = self.model, self.data
        gravity = pin.computeGeneralizedGravity
        gravity_derivatives = pin.computeGeneralizedGravityDerivatives
        masses = np.zeros(m) if payload_kg is None else np.asarray(payload_kg, dtype=float)
        try:
            for k in range(m):
                loaded = masses[k] != 0.0
                if loaded:
                    point = (np.zeros(3) if payload_point_m is None
                             else np.asarray(payload_point_m[k], float))
                    lever = self._joint_T_flange.act(point)
                    model.inertias[self._payload_joint] = (
                        self._bare_inertia + pin.Inertia(masses[k], lever, np.zeros((3, 3))))
                config = self._configuration(q_urdf[k])
                tau[k] = gravity(model, data, config)
                if derivatives:
                    dtau[k] = gravity_derivatives(model, data, config)
                if loaded:
                    model.inertias[self._payload_joint] = self._bare_inertia.copy()
        finally:
            model.inertias[self._payload_joint] = self._bare_inertia.copy()
        if not self._direct or model.nv != n:
            tau = tau[:, self._idx_v]
            if dtau is not None:
                dtau = dtau[:, self._idx_v][:, :, self._idx_v]
        return -tau, (None if dtau is None else -dtau)

    def load_torque(self, q_ctrl: np.ndarray, payload_kg: np.ndarray | None = None,
                    payload_point_m: np.ndarray | None = None, derivatives: bool = False):
        """Load torques (m, n) about the controller axes for controller axis values (m, n);
        with ``derivatives`` also d tau_ctrl / d q_ctrl (m, n, n). See the module docstring."""
        coupling = self.robot.urdf_from_controller
        tau, dtau = self.load_torque_urdf(self.robot.joints_from_controller(q_ctrl), payload_kg,
                                          payload_point_m, derivatives)
        if coupling is None:
            return tau, dtau
        tau = tau @ coupling
        if dtau is not None:
            dtau = coupling.T @ dtau @ coupling
        return tau, dtau


def gravity_model(robot: Robot) -> GravityModel:
    """The (cached) :class:`GravityModel` of ``robot``; inertials are part of the key."""
    key = (robot.fingerprint, hash(robot.urdf_text))
    if key not in _CACHE:
        if len(_CACHE) > 16:
            _CACHE.clear()
        _CACHE[key] = GravityModel(robot)
    return _CACHE[key]
