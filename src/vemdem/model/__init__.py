"""The seam between integrators and physics: the scene (bodies + contact + gravity) and the
body models (flexible VEM grains; rigid grains next)."""
