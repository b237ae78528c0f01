"""Depth from one snapshot: lenslet frames (micro-image disparity) and dual/quad-pixel views."""
