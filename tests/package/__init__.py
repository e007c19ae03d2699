"""Tests of the package as a whole: its layout, its top-level modules, its files."""
