"""Simulation and sensing: world files, the pybullet world with its ground truth, meshes, scans and
the simulated range sensors.
"""
