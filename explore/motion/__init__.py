"""Motion: robots, validity checking, OMPL planners, noisy execution and the planning clock."""
