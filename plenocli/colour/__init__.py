"""Colour: demosaicing of Bayer views, white balance, the camera's colour matrix, export.

Pure functions on numpy arrays (``demosaic``, ``balance``, ``matrix``, ``highlights``); the
``export`` and ``icc`` modules build the bytes of output-referred files (the stage writes them).
"""
