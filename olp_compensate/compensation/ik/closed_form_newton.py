"""Newton on the (calibrated) model in the coordinates of the nominal closed form, and the
closed-form fixed point onto the model: both keep the requested branch exactly.

Joints ``(m, 6)`` rad, targets ``(m, 4, 4)`` m in the base frame, branches ``cfx (m,)``.
"""

from __future__ import annotations

import numpy as np

from ...kinematics.conventions import invert_pose
from .closed_form import one_branch
from .families import OPWParameters
from .inputs import TWO_PI
from .jacobians import nominal_twist, rotation_from_rotvec
from .newton import model_poses_and_jacobian
from .normal_equations import DAMPING, gauss_newton_steps_t, joint_major, near_singular_t
from .opw import opw_forward
from .residuals import error_norms, pose_error
from .ur import ur_forward

_WILD = 1.0               # closed_form_newton: fixed-point step where |twist - e| > this |e|
_JOINT_STEP = 1e-6        # m and rad: errors below this are stepped in the joints
_FIXED_POINT_STEPS = 20
_FIXED_POINT_TOL = 1e-6    # rad: the closed-form iteration hands over to Newton below this


def closed_form_newton(params, fk_jacobian, T, cfx, q0, position_tol, rotation_tol,
                        max_steps, singular_tol, X0=None):
    """Newton on the model in the coordinates of the nominal closed form.

    The joints are ``q = IK_nominal(X)`` on branch ``cfx`` of a corrected target X (at first
    the target T). The model's error ``e`` at q asks for joint steps ``dq = J_model^-1 e``;
    they become a step of X along ``J_nominal dq``, and q is solved again in closed form.
    Near the shoulder and wrist singularities the joints are far from linear in the pose,
    while X is nearly linear in it (model and nominal differ by millimetres): this converges
    in two steps where Newton in q needs many, and it stays on the nominal branch. Without
    ``J_nominal`` (taking ``J_nominal = J_model``) it is the fixed point of
    :func:`closed_form_on_model`. ``X0``: the corrected targets to continue from (with
    ``q0`` their solutions). Returns q, singular (converged rows whose Jacobian is singular,
    see :func:`near_singular`), err (at q), steps, converged and X (of the rows not converged),
    per row; rows of ``q0`` with NaN are skipped. Errors below ``_JOINT_STEP`` are stepped
    in the joints (Newton there is as good, and saves the closed form)."""
    m, n = q0.shape
    q, X = q0.copy(), (T if X0 is None else X0).copy()
    forward = opw_forward if isinstance(params, OPWParameters) else ur_forward
    stale = np.zeros(m, bool)                 # X is not the one of q (a step in the joints)
    singular = np.zeros(m, bool)
    err = np.full((m, 6), np.nan)
    steps = np.zeros(m, int)
    converged = np.zeros(m, bool)
    act = np.flatnonzero(np.all(np.isfinite(q0), axis=1))
    q_a, X_a, T_a, cfx_a = q[act], X[act], T[act], cfx[act]
    for step in range(max_steps + 1):
        if len(act) == 0:
            break
        poses, jac = model_poses_and_jacobian(fk_jacobian, q_a, n)
        e = pose_error(T_a, poses)
        jt = joint_major(jac)                      # used before the model is called again
        position, rotation = error_norms(e)
        done = (position <= position_tol) & (rotation <= rotation_tol)
        leave = done | (step == max_steps)
        if np.any(leave):
            rows = act[leave]
            q[rows], err[rows], steps[rows] = q_a[leave], e[leave], step
            X[rows], converged[rows] = X_a[leave], done[leave]
            finished = np.flatnonzero(done)
            if len(finished):
                singular[act[finished]] = near_singular_t(jt[..., finished], singular_tol)
            keep = ~leave
            act, q_a, X_a, T_a, cfx_a = act[keep], q_a[keep], X_a[keep], T_a[keep], cfx_a[keep]
            if len(act) == 0:
                break
            jt, e = jt[..., keep], e[keep]
        dq = gauss_newton_steps_t(jt, e, DAMPING)
        # a step this close to the solution is as good in the joints: no closed form
        # (the corrected target X of such a row is brought up to date if it needs one)
        near = np.einsum("ij,ij->i", e, e) <= _JOINT_STEP ** 2
        q_a[near] += dq[near]
        stale[act[near]] = True
        far = np.flatnonzero(~near)
        if len(far) == 0:
            continue
        behind = far[stale[act[far]]]
        if len(behind):
            X_a[behind] = forward(params, q_a[behind])
            stale[act[behind]] = False
        q_f, X_f, e_f = q_a[far], X_a[far], e[far]
        twist = nominal_twist(params, q_f, dq[far])
        # J_nominal J_model^-1 is the identity but for millimetres over the distance to a
        # singularity; where it is far from it, the fixed-point step (twist = e) is safer
        wild = (np.einsum("ij,ij->i", twist - e_f, twist - e_f)
                > _WILD ** 2 * np.einsum("ij,ij->i", e_f, e_f))
        twist[wild] = e_f[wild]
        X_new = X_f.copy()
        X_new[:, :3, 3] += twist[:, :3]
        X_new[:, :3, :3] = rotation_from_rotvec(twist[:, 3:]) @ X_f[:, :3, :3]
        new = one_branch(params, X_new, cfx_a[far], clip=True)
        new += TWO_PI * np.round((q_f - new) / TWO_PI)
        ok = np.all(np.isfinite(new), axis=1)
        q_a[far] = np.where(ok[:, None], new, q_f)
        X_a[far] = np.where(ok[:, None, None], X_new, X_f)
    stale &= ~converged                       # the others' X are not used again
    if np.any(stale):
        X[stale] = forward(params, q[stale])
    return q, singular, err, steps, converged, X


def closed_form_on_model(params, fk_jacobian, T, cfx, q):
    """Closed-form iteration onto the model: ``q <- IK_nominal(T inv(E(q)))`` on branch cfx,
    with ``E(q) = inv(FK_nominal(q)) FK_model(q)`` the model's flange error. Keeps the
    requested branch exactly and is robust where Newton is not (near the shoulder and wrist
    singularities, whose closed form is exact); each step is one model evaluation.
    Returns q and the number of steps per row."""
    q = q.copy()
    steps = np.zeros(len(q), int)
    rows = np.flatnonzero(np.all(np.isfinite(q), axis=1))
    forward = opw_forward if isinstance(params, OPWParameters) else ur_forward
    for _ in range(_FIXED_POINT_STEPS):
        if len(rows) == 0:
            break
        model_pose = np.asarray(fk_jacobian(q[rows])[0], dtype=float)
        error = invert_pose(forward(params, q[rows])) @ model_pose
        corrected = T[rows] @ invert_pose(error)
        new = one_branch(params, corrected, cfx[rows], clip=True)
        new += TWO_PI * np.round((q[rows] - new) / TWO_PI)
        ok = np.all(np.isfinite(new), axis=1)
        moved = np.max(np.abs(new - q[rows]), axis=1)
        q[rows[ok]] = new[ok]
        steps[rows] += 1
        rows = rows[ok & (moved > _FIXED_POINT_TOL)]
    return q, steps
