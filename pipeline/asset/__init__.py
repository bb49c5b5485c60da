"""The completed model as an asset a robot can load: a watertight mesh of every stage
(:mod:`.meshing`), its mass properties (:mod:`.mass`), convex collision parts
(:mod:`.collision`), a URDF (:mod:`.urdf`), the symmetry plane in the robot's and the
object's frame (:mod:`.symmetry`), and the files a run writes (:mod:`.files`).

Everything but :mod:`.files` is pure geometry: arrays and meshes in, arrays and meshes out.
"""
