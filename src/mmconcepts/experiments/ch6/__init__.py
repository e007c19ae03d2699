"""Chapter 6. Multimodal concepts: one NMF over spoken words, gestures and objects.

Its experiments are one module per table or figure; what they share (data, splits, folds) is ``protocol``.
"""
