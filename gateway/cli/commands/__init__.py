"""One module per ``wheelgate`` subcommand, each exporting ``command``."""
