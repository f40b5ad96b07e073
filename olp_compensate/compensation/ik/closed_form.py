"""The closed forms of either family behind one call: forward, all eight branches, or one.

Branch k is configuration number k (``4 * behind + 2 * elbow + wrist``, see
:func:`.configuration.configuration_bits`; ABB's cfx on OPW arms); unreachable branches are NaN.
"""

from __future__ import annotations

import numpy as np

from .families import OPWParameters, URParameters, all_branches, check_family
from .inputs import as_poses, wrap
from .opw import opw_branch, opw_forward, opw_inverse
from .ur import ur_branch, ur_forward, ur_inverse


def one_branch(params, base_T_flange, branch, clip):
    """``(m, 6)`` controller joints on ``branch (m,)``, wrapped to (-pi, pi]."""
    solve_branch = opw_branch if isinstance(params, OPWParameters) else ur_branch
    theta = solve_branch(params, params._to_root(base_T_flange), branch, clip)
    return wrap(params.joint_angles(theta))


def closed_form_branch(params: OPWParameters | URParameters, base_T_flange, branch) -> np.ndarray:
    """The solution ``(m, 6)`` rad on ``branch (m,)`` (= ABB cfx) for flange poses
    ``(m, 4, 4)``, NaN where that branch cannot reach: one eighth of
    :func:`closed_form_inverse`'s work."""
    check_family(params)
    T = as_poses(base_T_flange, "base_T_flange")
    return one_branch(params, T, np.broadcast_to(np.asarray(branch, dtype=int), (len(T),)),
                       clip=False)


def closed_form_forward(params: OPWParameters | URParameters, q) -> np.ndarray:
    """:func:`opw_forward` or :func:`ur_forward`, whichever family ``params`` is."""
    check_family(params)
    return (opw_forward if isinstance(params, OPWParameters) else ur_forward)(params, q)


def closed_form_inverse(params: OPWParameters | URParameters, base_T_flange,
                        clip: bool = False) -> np.ndarray:
    """:func:`opw_inverse` or :func:`ur_inverse`, whichever family ``params`` is.

    ``clip``: poses out of reach get the joints of the stretched arm towards them instead
    of NaN (a start for a closest-approach search)."""
    check_family(params)
    if clip:
        return closed_form_solutions(params, as_poses(base_T_flange, "base_T_flange"), clip=True)
    return (opw_inverse if isinstance(params, OPWParameters) else ur_inverse)(params,
                                                                            base_T_flange)


def closed_form_solutions(params, T, clip):
    """All 8 branches ``(m, 8, 6)`` rad of flange poses ``T (m, 4, 4)`` m (checked already);
    ``clip`` as in :func:`closed_form_inverse`."""
    solve_branch = opw_branch if isinstance(params, OPWParameters) else ur_branch
    return all_branches(solve_branch, params, T, clip)
