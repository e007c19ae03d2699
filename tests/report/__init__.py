"""Tests of mmconcepts.report."""
