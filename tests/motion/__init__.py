"""Tests of mmconcepts.motion."""
