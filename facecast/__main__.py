from facecast.cli import entry

raise SystemExit(entry())
