"""Time integrators, Newton's method and linear solvers."""
