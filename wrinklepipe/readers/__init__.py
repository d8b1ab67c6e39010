"""Reading any mesh or package file by its suffix: the one reader table and mesh ingest.

- :mod:`wrinklepipe.readers.registry`: the formats wrinklepipe reads (glTF, USD, OBJ), keyed by
  suffix (trimesh's loader table), with their mesh and package readers;
- :mod:`wrinklepipe.readers.meshes`: mesh ingest (``load_meshes`` / ``load_mesh``, UVs made
  with xatlas where a mesh has none);
- :mod:`wrinklepipe.readers.obj`: the OBJ reader; :mod:`wrinklepipe.readers.rig`: a skinned
  glTF as the ``bones`` driver reads it.

The table sits above :mod:`wrinklepipe.gltf` and :mod:`wrinklepipe.usd` (it names their
readers), so it cannot live in :mod:`wrinklepipe.io`, which they read pixels and JSON through.
This ``__init__`` imports nothing.
"""
