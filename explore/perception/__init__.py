"""Perception: segmentation, recognition, registration, PVS validation of hypotheses, and the
object database.
"""
