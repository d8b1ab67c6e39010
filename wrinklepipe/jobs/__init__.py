"""Whole runs: each reads its inputs, runs stages, validates where it should and writes one
folder through :func:`wrinklepipe.atomic.staged_folder` (all or nothing).

- :mod:`~wrinklepipe.jobs.convert`: ``convert(manifest, out, ConvertOptions())``: ingest ->
  prepare -> drivers -> package -> :mod:`wrinklepipe.outputs` -> :mod:`~wrinklepipe.jobs.validation`
  -> the report;
- :mod:`~wrinklepipe.jobs.bake`: a driver evaluated over time (curves, pre-blended maps);
- :mod:`~wrinklepipe.jobs.export`: a converted asset for an engine;
- :mod:`~wrinklepipe.jobs.capture`: a wrinkle map captured from photographs;
- :mod:`~wrinklepipe.jobs.pack_masks`: region masks packed into textures;
- :mod:`~wrinklepipe.jobs.regions`: masks and driver rows from a mesh's morph targets.

A command (:mod:`wrinklepipe.commands`) parses its arguments and calls one job. This
``__init__`` imports nothing, so importing one job runs no other.
"""
