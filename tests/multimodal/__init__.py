"""Tests of mmconcepts.multimodal."""
