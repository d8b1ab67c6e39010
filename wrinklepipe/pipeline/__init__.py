"""The conversion pipeline: stages on plain data, and ``convert``, their composition.

- :mod:`~wrinklepipe.pipeline.ingest`: manifest + files -> :class:`WrinkleAsset`;
- :mod:`~wrinklepipe.pipeline.prepare`: resampling (``auto`` sizes), the mesh stage (normals,
  MikkTSpace tangents, vertex IDs), the PD scale;
- :mod:`~wrinklepipe.pipeline.drivers`: the manifest's drivers -> weight curves;
- packaging (encode + pack) is :func:`wrinklepipe.pipeline.package.package_from_asset`;
- :mod:`~wrinklepipe.jobs.convert`: ``convert(manifest, out, ConvertOptions())``, the whole
  run into one folder (writing through :mod:`wrinklepipe.outputs`, then
  :mod:`~wrinklepipe.jobs.validation`).

The stage modules sit below the validator (it may use them); ``convert`` and ``validation``
sit above it and the sources layer. This file imports nothing, so importing a stage never pulls
in the composition.
"""
