"""Tactile plugins: the taxel contacts of an executed grasp."""
