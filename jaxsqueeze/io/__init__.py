"""Input/output layer: TOML scene files and the command line."""
