"""Running the stages: a simulated trial, fusion on recorded data, completing every
object of a recorded view, and the result document each of them writes."""
