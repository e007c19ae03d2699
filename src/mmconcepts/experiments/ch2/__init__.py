"""Chapter 2. Background: NMF recovers a known dictionary.

Its experiments are one module per table or figure.
"""
