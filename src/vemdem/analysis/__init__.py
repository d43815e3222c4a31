"""Closed-form references, measurements and plots."""
