"""Multimodal concepts: the multimodal NMF learner and cross-modal matching (thesis chapter 6).

MultimodalNMF
    I-divergence NMF over stacked, L1-normalised modalities; internal representations
    from any subset of modalities (eq. 6.3); reconstruction of any modality; save/load
    without pickle.
crossmodal_distances, matching_success_rate, pairwise_divergence
    The cross-modal matching protocol of section 6.6.1 (Fig. 6.3): comparison in the
    internal, test or reference space with KL, reversed or symmetric KL, Euclidean or
    cosine dissimilarities.
paired_dataset, PairedDataset
    Your own recordings as a paired multimodal data set: paired by concept (shared labels,
    a random label correspondence, or a pairing CSV), split by recording into training,
    test and reference parts, with the features of each modality fitted on training.
top_examples, atom_label_association
    What a learnt concept is: the examples that express each atom most, the share of
    each atom's activation that falls on each label.
mutual_information_matrix
    The information each learnt coefficient carries about each concept (section 6.6.3,
    Fig. 6.10).
"""

from .learner import FORMAT_VERSION, MultimodalNMF
from .matching import METRICS, SPACES, crossmodal_distances, matching_success_rate, pairwise_divergence
from .concepts import atom_label_association, top_examples
from .metrics import mutual_information_matrix
from .paired import DEFAULT_PARTS, PairedDataset, paired_dataset

__all__ = [
    "DEFAULT_PARTS",
    "PairedDataset",
    "paired_dataset",
    "FORMAT_VERSION",
    "METRICS",
    "SPACES",
    "atom_label_association",
    "MultimodalNMF",
    "crossmodal_distances",
    "matching_success_rate",
    "mutual_information_matrix",
    "pairwise_divergence",
    "top_examples",
]
