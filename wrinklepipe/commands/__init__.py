"""One module per subcommand (see :mod:`wrinklepipe.cli`)."""
