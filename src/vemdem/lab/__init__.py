"""The laboratory: the servo law, one load path (stages over servo walls and constant-speed
drives), the box cell a sample is tested in, and the one run and summary every lab test shares.
Scenarios (oedometer, triaxial, direct shear, isotropic) build a cell and a path from their config
tables and name their measures; this room never reads a config."""
