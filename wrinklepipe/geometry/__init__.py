"""Geometry stages: vertex IDs (spatial hash), MikkTSpace tangents, dynamic wrinkle weights.

Pure functions on numpy arrays; mesh file I/O lives in :mod:`wrinklepipe.io.mesh`. See
``docs/geometry.md``.
"""
