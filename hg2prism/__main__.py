from hg2prism.cli import entry

raise SystemExit(entry())
