"""Tests of mmconcepts.engine."""
