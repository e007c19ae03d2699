"""mmconcepts: the emergence of multimodal concepts, reimplemented.

A library and command-line tool implementing the systems of O. Mangin's PhD thesis
"The emergence of multimodal concepts: from perceptual motion primitives to grounded
acoustic words" (2014): beta-divergence nonnegative matrix factorization with masks and
partial transforms (``mmconcepts.nmf``), motion histograms (``mmconcepts.motion``),
sound features and the acoustic cluster tree (``mmconcepts.sound``), image features
(``mmconcepts.vision``), factorial inverse reinforcement learning (``mmconcepts.tasks``),
the multimodal learner (``mmconcepts.multimodal``), and one experiment per thesis table
or figure (``mmconcepts.experiments``).
"""

from __future__ import annotations

__version__ = "0.2.0.dev0"

__all__ = ["__version__"]
