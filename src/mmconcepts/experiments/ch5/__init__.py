"""Chapter 5. Primitive sounds and words: the acoustic cluster tree, HAC features and NMF.

Its experiments are one module per table or figure; what they share (data, splits, folds) is ``protocol``.
"""
