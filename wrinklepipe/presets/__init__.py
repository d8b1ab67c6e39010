"""Published tables and layouts, as data."""
