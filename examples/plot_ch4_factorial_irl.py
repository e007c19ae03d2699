"""
Factorial inverse reinforcement learning on a grid world
========================================================

Section 4.3 of the thesis learns *primitive tasks* from demonstrations of many composite
tasks: each demonstrated task's reward is a mixture ``theta = D h`` of a few rewards of an
unknown dictionary ``D``, and :class:`~mmconcepts.tasks.FactorialIRL` learns ``D`` and the
mixing coefficients together by alternating gradient steps on the summed GradIRL losses of
all tasks (eq. 4.8-4.10), starting from a PCA of flat per-task solutions.

The learnt dictionary pays off on **new** tasks: from a single demonstration, a reward
expressed on the learnt primitives is found far better than a flat, tabular reward.

Sizes are small here (a 6 x 6 grid, 3 primitives, 20 tasks) so that the example runs in
seconds; ``mmconcepts run ch4-factorial-irl`` runs the thesis' protocol.
"""

# %%
# A grid world and tasks mixing three primitive rewards
# -----------------------------------------------------
# Moves succeed with probability 0.7, discount 0.9 (the thesis' world, smaller). Each task
# mixes 2 or 3 of the primitives; its expert acts greedily on the task's optimal values.
import matplotlib.pyplot as plt
import numpy as np

from mmconcepts.tasks import (
    FactorialIRL, GradIRL, greedy_policy, grid_world, policy_evaluation, sample_trajectories,
    uniform_policy, value_iteration,
)

rng = np.random.default_rng(0)
mdp = grid_world(6, success_prob=0.7, discount=0.9)
S, A, k = mdp.n_states, mdp.n_actions, 3
D_true = rng.standard_normal((k, S * A))  # tabular primitive rewards


def make_tasks(n_tasks, n_demos):
    H = np.zeros((n_tasks, k))
    for i in range(n_tasks):
        idx = rng.choice(k, size=int(rng.integers(2, 4)), replace=False)
        H[i, idx] = rng.uniform(0.5, 1.5, idx.size)
    R = (H @ D_true).reshape(n_tasks, S, A)
    policies = greedy_policy(value_iteration(mdp, R)[1])
    demos = [sample_trajectories(mdp, policies[i], n_demos, 10, random_state=rng) for i in range(n_tasks)]
    return R, demos


R_train, demos_train = make_tasks(20, 5)  # 20 tasks, 5 demonstrations of 10 steps each
R_new, demos_new = make_tasks(10, 1)  # new tasks, one demonstration each
print(f"{S} states, {A} actions; {len(demos_train)} training tasks; a demonstration is", demos_train[0][0].shape)


def deviation(learnt, true):
    """Score of eq. (4.11) as a deviation: value lost by acting greedily on the learnt
    reward, relative to the random policy's loss (0: optimal, 1: no better than random)."""
    V = policy_evaluation(mdp, greedy_policy(value_iteration(mdp, learnt)[1]), true).mean(1)
    opt = value_iteration(mdp, true)[0].mean(1)
    rnd = policy_evaluation(mdp, np.broadcast_to(uniform_policy(mdp), true.shape), true).mean(1)
    return (opt - V) / (opt - rnd)


# %%
# Flat and factorial learners on the training tasks
# -------------------------------------------------
flat = GradIRL(beta=1.0, max_iter=50).fit(mdp, demos_train)  # one tabular reward per task
fact = FactorialIRL(k, beta=1.0, max_iter=40, random_state=0).fit(mdp, demos_train, flat_theta=flat.theta_)
print("factorial dictionary:", fact.components_.shape, "coefficients:", fact.coefficients_.shape)
print(f"training tasks, mean deviation: flat {deviation(flat.rewards_, R_train).mean():.3f}, "
      f"factorial {deviation(fact.rewards_, R_train).mean():.3f}")

# %%
# New tasks from one demonstration
# --------------------------------
# The factorial learner's atoms become reward features (S, A, k) for GradIRL: a new task
# only needs its k coefficients.
features = fact.reward_features(mdp)
on_atoms = GradIRL(features, beta=1.0, max_iter=50).fit(mdp, demos_new)
flat_new = GradIRL(beta=1.0, max_iter=50).fit(mdp, demos_new)
scores = {"flat (tabular)": deviation(flat_new.rewards_, R_new),
          "on the learnt primitives": deviation(on_atoms.rewards_, R_new)}
for name, s in scores.items():
    print(f"new tasks, one demonstration, {name}: {s.mean():.3f}")

# %%
# Deviation from the optimal behaviour on the new tasks
# -----------------------------------------------------
fig, ax = plt.subplots(figsize=(7, 3.2))
names = list(scores)
ax.boxplot([scores[n] for n in names], orientation="horizontal")
ax.set_yticks([1, 2], names)
ax.axvline(1.0, color="0.5", ls="--", label="random policy")
ax.axvline(0.0, color="k", lw=0.8)
ax.set(xlabel="normalised deviation from the optimal value (lower is better)",
       title="Transfer to new tasks from one demonstration")
ax.legend(loc="lower right")
fig.tight_layout()
plt.show()
