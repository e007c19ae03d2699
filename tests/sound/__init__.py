"""Tests of mmconcepts.sound."""
