"""Outputs: what convert writes, from a packed asset.

- :mod:`~wrinklepipe.outputs.compression`: the block-format choice (DDS + KTX2 within budget);
- :mod:`~wrinklepipe.outputs.curves`: weight curves as CSV + JSON;
- :mod:`~wrinklepipe.outputs.folder`: every file of the folder, and writing it (USD included);
- :mod:`~wrinklepipe.outputs.report`: report.json and report.html.
"""
