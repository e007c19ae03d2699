"""Chapter 3. Simultaneous dance gestures: a dictionary of primitive motions learnt from label sets.

Its experiments are one module per table or figure; what they share (data, splits, folds) is ``protocol``.
"""
