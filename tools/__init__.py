"""Command-line wrappers (installed as the ``mrsteer_cli`` package, command ``mrsteer``)."""
