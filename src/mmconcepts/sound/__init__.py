"""Primitive sounds: audio, MFCC, DTW, the incremental cluster tree, TF-IDF voting, HAC,
and speech data (thesis chapter 5 and Appendix B.1).
"""
