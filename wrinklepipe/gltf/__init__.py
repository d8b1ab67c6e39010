"""glTF 2.0: the container, the document model, accessors, primitives, decompression, writing.

The source document follows glTF-Transform's design: read whole, add to, write back.

- :func:`wrinklepipe.gltf.document.read_document` -> :class:`~wrinklepipe.gltf.document.Document`
  (the source JSON tree + the bytes of every bufferView and external image; meshopt and Draco
  geometry decoded),
- the ``Document.add_*`` methods append what the pipeline adds,
- :func:`wrinklepipe.gltf.write.write_document` / ``document_files`` write it back (one buffer),
- :mod:`wrinklepipe.gltf.inspect` summarises a document and lists what differs between two.

This ``__init__`` imports nothing, so importing one module of the package runs no other.
"""
