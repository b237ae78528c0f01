"""Depth from one snapshot: lenslet frames (micro-image disparity) and dual/quad-pixel views."""

# Largest dual/quad-pixel disparity searched (px). A half-pixel view's defocus disc grows with
# the disparity (radius 3 pi d / 8 for a sharp half-pupil): past about 8 px what is left of the
# texture after its blur is mostly the disc's side lobes, whose phase does not follow the
# shift, and the 15 px window matches them at wrong shifts with clear confidence (simulated
# bands of 16-31 px read 7-15 px, signs flipped, searching 24-32 px). 12 keeps the Pixel 4
# scene's 3-9 px (docs/depth.md).
MAX_DISPARITY = 12.0
