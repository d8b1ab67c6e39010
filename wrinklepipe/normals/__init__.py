"""Normal maps: ingest, green convention, PD / diff / full encodings, resampling, block
compression checks (BC5, BC1, BC3nm, BC7, optional UASTC), DDS and KTX2 containers, footprint.

Modules: :mod:`.read`, :mod:`.convention`, :mod:`.encode`, :mod:`.resample`, :mod:`.compress`,
:mod:`.dds`, :mod:`.ktx2`, :mod:`.uastc`, :mod:`.footprint`, :mod:`.job` (the ``encode-normals``
job). See docs/normals.md for the API summary.
"""
