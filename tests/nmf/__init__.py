"""Tests of mmconcepts.nmf."""
