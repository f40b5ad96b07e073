"""Inverse kinematics: closed forms of the nominal robot, Newton refinement on any model.

Everything is batched over targets: poses ``(m, 4, 4)`` in metres, joint vectors ``(m, n)``
in radians, the user's joint convention (signs and zero positions of the controller). The
modules follow the pipeline:

- :mod:`.families` (:class:`OPWParameters`, :class:`URParameters`), :mod:`.opw`
  (:func:`opw_forward`, :func:`opw_inverse`: ortho-parallel base and spherical wrist, after
  Brandstoetter et al. 2014), :mod:`.ur` (:func:`ur_forward`, :func:`ur_inverse`: axes 2,
  3, 4 parallel, after Hawkins 2013), :mod:`.closed_form` (either family behind one call);
- :mod:`.configuration`: :func:`configuration_bits`, :func:`branch_of`,
  :func:`select_branch`, :func:`nominal_joints_on_branch` (ABB-style confdata);
- :mod:`.fitting`: :func:`fit_family`, which family a forward-kinematics callable belongs
  to, and its parameters, verified to 1e-9 m / 1e-9 rad;
- :mod:`.newton`: :func:`refine`, damped Newton on any model given as ``fk_jacobian``
  (with :mod:`.normal_equations`, :mod:`.residuals`, :mod:`.jacobians`);
- :mod:`.closed_form_newton`: Newton on the model in the closed form's coordinates;
- :mod:`.reach`: :class:`ReachBound`, a proof that targets lie beyond a 6R chain's reach;
- :mod:`.solver`: :func:`solve`, :func:`solve_with_nominal`: closed form on the nominal
  family, then Newton on the (calibrated) model (two steps for most targets), Newton from
  several starts for the rest.

Branch numbering. The 8 solutions of both closed forms are ordered so that the index *is*
the configuration number: ``index = 4 * behind + 2 * elbow + wrist``, with the three bits of
:func:`configuration_bits`. For OPW arms this is ABB's ``cfx`` (see
:mod:`olp_compensate.programs.object_model.confdata`). Unreachable branches are NaN. Failure of an
iterative solve is a value in :class:`IKSolution`, never an exception.
"""

from .closed_form import closed_form_branch, closed_form_forward, closed_form_inverse
from .configuration import branch_of, configuration_bits, nominal_joints_on_branch, select_branch
from .families import OPWParameters, URParameters
from .fitting import fit_family
from .newton import refine
from .opw import opw_forward, opw_inverse
from .reach import ReachBound
from .solution import REASONS, IKSolution
from .solver import solve, solve_with_nominal
from .ur import ur_forward, ur_inverse


__all__ = [
    "OPWParameters", "URParameters", "IKSolution", "REASONS",
    "opw_forward", "opw_inverse", "ur_forward", "ur_inverse",
    "closed_form_forward", "closed_form_inverse", "closed_form_branch", "configuration_bits",
    "branch_of", "select_branch", "nominal_joints_on_branch", "fit_family", "refine", "solve",
    "solve_with_nominal", "ReachBound",
]
