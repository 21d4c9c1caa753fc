"""What the robot knows: the probabilistic voxel space (PVS), the surface model, visibility /
information-gain ray casting, and the ground-truth metrics of a model.
"""
