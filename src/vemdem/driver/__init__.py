"""The shared time loop of every dynamic scenario: frames, checkpoints, stop and control hooks."""
