"""Visuo-tactile state estimation: geometry, correspondences, the structured IEKF, its dense
reference, the self-diagnosis and the ICP baseline. Pure array code, no I/O.

The package namespace re-exports nothing: importing it must stay cheap, since every
estimator plugin's module imports from here when ``symfuse plugins`` lists them; the
kernels (and scipy) load when an estimate runs.
"""
