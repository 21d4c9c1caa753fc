"""Runtime: the plugin registry and hooks, behaviour trees, runs and their outputs, comparisons and
reports.
"""
