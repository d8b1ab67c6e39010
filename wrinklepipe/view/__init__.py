"""``wrinklepipe view``: a local three.js page that previews a converted character.

:mod:`~wrinklepipe.view.server` serves the viewer (``wrinklepipe/data/viewer``), the GLTFLoader
plugin (``wrinklepipe/data/threejs``), three.js from the npm install under ``tools/node`` (no CDN)
and the asset's folder, on the loopback interface only.
"""
