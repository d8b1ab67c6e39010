"""wrinklepipe: asset-pipeline processor and validator for animated facial wrinkle maps."""

__version__ = "0.1.0"
