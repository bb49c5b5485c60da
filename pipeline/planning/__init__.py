"""Grasp planning: candidate grasps for each hand, their geometry and predicted pad
contacts, the choice of hand, and where to grasp next."""
