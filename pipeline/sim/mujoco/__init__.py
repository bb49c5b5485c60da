"""MuJoCo simulation: the same table, object and hands as the PyBullet world, compiled by
MuJoCo, for the built-in ``mujoco`` world plugin (:mod:`plugins.worlds.mujoco_world`).

* :mod:`.scene` builds the model (an ``MjSpec``): the table, the object (its mesh for the
  camera, convex parts for contacts) and a hand compiled from the project's URDF in
  ``robots/``, its palm welded to a mocap target;
* :mod:`.hand` drives the hand: joint servos, pad probes and contact forces;
* :mod:`.camera` renders depth, colour and the object mask by ray casting (no GL);
* :mod:`.world` holds the model and its state and runs the grasp sequence of
  :mod:`pipeline.sim.grasp_sequence` in it.

Needs the ``mujoco`` package (``pip install 'symfuse[mujoco]'``); the modules import it.
"""
