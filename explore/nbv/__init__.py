"""Next-best-view: candidates, scan planning, Kriegel's next-best-scan modelling session and
Vasquez-Gomez view/state planning.
"""
