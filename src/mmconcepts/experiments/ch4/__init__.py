"""Chapter 4. Primitive tasks: factorial inverse control and factorial inverse reinforcement learning.

Its experiments are one module per table or figure.
"""
