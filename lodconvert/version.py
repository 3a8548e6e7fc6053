"""The version of lodconvert, which every output records (``asset.generator`` and the like)."""

__version__ = "0.1.0"
