"""Blender-free tests of core/, one folder per core package."""
