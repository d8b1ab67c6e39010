"""USD (usd-core): reading, layering over a source, the scene, looks, animation, writing.

- :mod:`wrinklepipe.usd.meshes`: the one USD mesh reader (render vertices, primvars, UsdSkel);
- :mod:`wrinklepipe.usd.poses`: a mesh's joint matrices and blend-shape weights at a time;
- :mod:`wrinklepipe.usd.source`: a USD source read for conversion (which meshes get wrinkled);
- :mod:`wrinklepipe.usd.layer`: the output of a USD source, a layer over it, and a flat usdz;
- :mod:`wrinklepipe.usd.scene`, ``looks``, ``animation``: a glTF source's document as USD;
- :mod:`wrinklepipe.usd.package_write` / ``package_read``: a wrinkle package as a USD stage;
- :mod:`wrinklepipe.usd.inspect`: what ``wrinklepipe inspect`` lists of a stage.

``pxr`` is imported inside the functions that need it (about 0.3 s and its plugin registry).
This ``__init__`` imports nothing, so importing one module of the package runs no other.
"""
