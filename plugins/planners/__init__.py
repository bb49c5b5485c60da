"""Planner plugins: a grasp on the completed model."""
