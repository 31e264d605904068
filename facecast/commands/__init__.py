"""One module per ``facecast`` subcommand (see facecast/cli.py for the contract)."""
