"""Tests of the thesis' experiments (mmconcepts.experiments)."""
