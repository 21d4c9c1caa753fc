"""explore: active scene exploration with a robot and a range sensor.

The library knows nothing about behaviour trees; everything a behaviour does can be done
from a Python script with the objects defined here.
"""

__version__ = "0.1.0"
