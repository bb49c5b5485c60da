"""PyBullet simulation: the scene, the world, cameras and depth-sensor models, and hands."""
