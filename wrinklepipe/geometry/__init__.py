"""Geometry stages: vertex IDs (spatial hash), MikkTSpace tangents, dynamic wrinkle weights.

Pure functions on numpy arrays; mesh file I/O lives in :mod:`wrinklepipe.readers.meshes`. See
``docs/geometry.md``.
"""
