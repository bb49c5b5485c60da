"""World plugins: the simulated (or recorded) scene a trial runs in."""
