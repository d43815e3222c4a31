"""Runs on purpose, to check vemdem against independent references (a refined FEM model)."""
