"""The glTF source document (glTF-Transform's design): read whole, add to, write back.

- :func:`read_document` -> :class:`Document` (the source JSON tree + the bytes of every
  bufferView and external image; meshopt and Draco geometry decoded),
- the ``Document.add_*`` methods append what the pipeline adds,
- :func:`write_document` / :func:`document_files` write it back (one buffer),
- :mod:`wrinklepipe.document.inspect` summarises a document and lists what differs between two.
"""

from wrinklepipe.document.model import Document, PrimitiveRef, read_document
from wrinklepipe.document.write import document_files, pack, write_document

__all__ = [
    "Document",
    "PrimitiveRef",
    "document_files",
    "pack",
    "read_document",
    "write_document",
]
