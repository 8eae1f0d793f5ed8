"""Built-in scene files (TOML) for the command line: the foam square and the heart and leaf bands."""
