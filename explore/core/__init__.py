"""Foundations every layer uses: errors, typed arrays, parameters, user files and output paths,
outcomes, decisions with margins, determinism, SE(3) geometry, pictures.
"""
