"""Estimator plugins: fusing the contacts with the view."""
