"""Sensor plugins: depth views of the world."""
