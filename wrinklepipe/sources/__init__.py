"""Sources: turn a manifest, an output folder or a file into pipeline or validation inputs.

- :mod:`wrinklepipe.sources.validation`: ``load_input(PATH)`` -> :class:`ValidationInput` (a
  convert folder, glTF/GLB, USD, a manifest before conversion, a bundle, ``demo...``);
- :mod:`wrinklepipe.sources.package`: ``read_package(PATH)`` -> :class:`WrinklePackage` (what
  ``export`` reads).

This layer sits above both the pipeline stages and the validator; neither imports it.
"""
