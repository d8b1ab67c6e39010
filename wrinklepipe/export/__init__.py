"""Engine exports: a converted asset the way Unreal, Unity, Godot or Blender want it.

- :mod:`~wrinklepipe.export.presets`: one :class:`EnginePreset` per engine;
- :mod:`~wrinklepipe.export.shaders`: the combine-function snippets (HLSL, GLSL);
- :mod:`~wrinklepipe.export.files`: a package -> the export's files (``export_files``);
- :mod:`~wrinklepipe.export.job`: ``export(SOURCE, OUT, engine)``, read + files + staged write.
"""
