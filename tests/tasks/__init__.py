"""Tests of mmconcepts.tasks."""
