"""Scene exploration: the scene session (segment, recognise, validate, model, store), its motion,
views, patrol and metrics.
"""
