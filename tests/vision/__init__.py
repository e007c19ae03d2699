"""Tests of mmconcepts.vision."""
