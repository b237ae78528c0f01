"""plenocli: raw-processing pipeline for plenoptic captures (dual-pixel, Raytrix, N x N sensors)."""

__version__ = "0.1.0"
