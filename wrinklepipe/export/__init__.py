"""Engine exports: a converted asset the way Unreal, Unity, Godot or Blender want it.

- :mod:`~wrinklepipe.export.presets`: one :class:`EnginePreset` per engine;
- :mod:`~wrinklepipe.export.gltf`: the mesh as the engine imports it (glTF without the extension);
- :mod:`~wrinklepipe.export.textures`: textures in the engine's format and convention (codec);
- :mod:`~wrinklepipe.export.files`: a package -> the export's files (``export_files``), with the
  shaders of :mod:`wrinklepipe.shading` and the runtime code of ``wrinklepipe/data/engines``;
- :mod:`~wrinklepipe.export.readme`: the folder's README (import steps);
- :mod:`~wrinklepipe.jobs.export`: ``export(SOURCE, OUT, engine)``, read + files + staged write.
"""
