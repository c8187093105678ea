from hg2prism.program import entry

raise SystemExit(entry())
