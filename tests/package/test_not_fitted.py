"""Every learner says "not fitted" the same way: scikit-learn's NotFittedError."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.exceptions import NotFittedError


def _cases():
    from mmconcepts.motion import MotionHistograms
    from mmconcepts.multimodal import MultimodalNMF
    from mmconcepts.nmf import NMF, LabelNMF
    from mmconcepts.sound.hac import HAC
    from mmconcepts.sound.tree import ClusterTree
    from mmconcepts.sound.voting import EventVoting, TreeVotingClassifier
    from mmconcepts.tasks.factorial import FactorialIRL
    from mmconcepts.tasks.inverse_control import FactorialInverseControl
    from mmconcepts.tasks.mdp import grid_world

    X = np.ones((4, 3))
    seqs = [np.ones((20, 13)), np.ones((25, 13))]
    return [
        ("NMF.transform", lambda: NMF(2).transform(X)),
        ("LabelNMF.decision_function", lambda: LabelNMF(2).decision_function(X)),
        ("HAC.transform", lambda: HAC().transform(seqs)),
        ("ClusterTree.predict", lambda: ClusterTree(1.0).predict(X)),
        ("MotionHistograms.transform", lambda: MotionHistograms().transform([np.zeros((10, 4))])),
        ("EventVoting.predict", lambda: EventVoting().predict([np.array([0, 1])])),
        ("TreeVotingClassifier.predict", lambda: TreeVotingClassifier(1.0).predict([np.ones((3, 4))])),
        ("FactorialIRL.reward_features", lambda: FactorialIRL(2).reward_features(grid_world(3))),
        ("FactorialInverseControl.transform", lambda: FactorialInverseControl(2).transform([np.zeros((5, 2))])),
        ("MultimodalNMF.transform", lambda: MultimodalNMF(2).transform({"sound": X})),
    ]


@pytest.mark.parametrize("name, call", _cases(), ids=[c[0] for c in _cases()])
def test_using_an_unfitted_learner_raises_not_fitted_error(name, call):
    with pytest.raises(NotFittedError) as info:
        call()
    assert isinstance(info.value, ValueError)  # callers catching ValueError (our errors' base) still catch it
    assert "fit" in str(info.value)  # the message says what to do
