"""piga: physics-as-inverse-graphics. Learn a system's parameters and states from video.

Small public API; the modules hold the details.
"""

__version__ = "0.1.0"
