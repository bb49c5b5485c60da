"""Symmetry initialiser plugins: the first estimate of the symmetry plane."""
