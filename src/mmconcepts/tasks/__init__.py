"""Tasks: MDPs, planning, gradient IRL, factorial IRL and factorial inverse feedback control.

Thesis chapter 4 (sections 4.2 and 4.3) and the background of section 2.2.

Learners that do not take arrays
--------------------------------
The learners of this package follow scikit-learn's contract (parameters in ``__init__``,
:func:`~sklearn.base.clone`, ``get_params``/``set_params``, fitted attributes ending in
``_``, saved and loaded without pickle), but what they learn from is not a matrix of
examples, so they have no ``transform`` and do not go in a
:class:`~sklearn.pipeline.Pipeline`:

- :class:`GradIRL`, :class:`MaxEntIRL` and :class:`FactorialIRL` learn from an :class:`MDP`
  and demonstrations, ``fit(mdp, demonstrations)``: one list of trajectories per task, a
  trajectory an int array of states and actions (:func:`sample_trajectories` draws them);
- :class:`FactorialInverseControl` learns from trajectories of a dynamical system,
  ``fit(trajectories, coefficients=None)``: a list of arrays of shape (n_steps, 2).

Their inputs are checked by :func:`mmconcepts.tasks.mdp.check_trajectories` and
:func:`mmconcepts.tasks.irl.check_task_demonstrations`, which say what is expected when
something else is given.
"""

from .factorial import FactorialIRL, component_features, factorial_objective
from .irl import (
    GradIRL,
    MaxEntIRL,
    adjoint_gradient,
    armijo_descent,
    empirical_policy,
    gradirl_objective,
    maxent_objective,
    q_gradient,
)
from .mdp import (
    MDP,
    boltzmann_policy,
    greedy_policy,
    grid_world,
    policy_evaluation,
    policy_iteration,
    policy_transitions,
    q_values,
    sample_trajectories,
    soft_value_iteration,
    uniform_policy,
    value_iteration,
)
from .inverse_control import (
    FactorialInverseControl,
    RBFFeatures,
    brillinger_regression,
    control_trajectories,
    relative_l2_error,
)

__all__ = [
    "MDP", "grid_world", "value_iteration", "policy_iteration", "soft_value_iteration", "policy_evaluation", "q_values",
    "greedy_policy", "boltzmann_policy", "uniform_policy", "policy_transitions", "sample_trajectories",
    "empirical_policy", "gradirl_objective", "q_gradient", "adjoint_gradient", "maxent_objective",
    "armijo_descent", "GradIRL", "MaxEntIRL", "FactorialIRL", "factorial_objective", "component_features",
    "RBFFeatures", "control_trajectories", "brillinger_regression", "FactorialInverseControl",
    "relative_l2_error",
]
