"""Chapter 7. Perspectives: compositional and online multimodal learning.

Its experiments are one module per table or figure; what they share (data, splits, folds) is ``protocol``.
"""
