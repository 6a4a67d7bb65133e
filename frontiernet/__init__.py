"""frontiernet: visual frontier learning (FrontierNet, RA-L 2025).

The library: scenes, the ray-cast simulator, depth sources, and (in later
modules) the model, frontier anchoring, mapping, planning and exploration.
"""

__version__ = "0.1.0"

from .errors import InputError  # noqa: F401
