"""USD source documents (moving to :mod:`wrinklepipe.usd`); the glTF document is
:mod:`wrinklepipe.gltf`."""
