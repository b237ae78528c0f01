"""Optics: glass indices (Sellmeier), lens prescriptions, exact ray tracing, lens reports,
prism deviation and sub-aperture cross-talk of a quad-pixel sensor behind a real lens.

Pure functions on numpy arrays; files are read by :mod:`plenocli.io.lensfile`.
"""
